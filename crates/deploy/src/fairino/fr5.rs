//! The FR5's figures the deployment checks against: FAIRINO's published joint limits and
//! speeds (the controller's joint angles are the URDF's, in degrees), and the MoveJ
//! acceleration the twin models at 100 %.

/// Six joint values (deg, deg/s or deg/s²), j1 to j6.
pub type Joints = [f64; 6];

/// Joint limits (deg): j1, j5 and j6 ±175, j2 and j4 −265 to 85, j3 ±162.
pub const JOINT_LIMITS_DEG: [(f64, f64); 6] = [
    (-175.0, 175.0),
    (-265.0, 85.0),
    (-162.0, 162.0),
    (-265.0, 85.0),
    (-175.0, 175.0),
    (-175.0, 175.0),
];

/// Joint speed limits (deg/s): 3.15 rad/s for j1–j3, 3.2 rad/s for j4–j6.
pub const MAX_SPEED_DEG_S: Joints = [180.48, 180.48, 180.48, 183.35, 183.35, 183.35];

/// The slowest joint's top speed (deg/s): MoveJ's `vel` is a percentage of it.
pub const MOVE_J_FULL_SPEED_DEG_S: f64 = 180.48;

/// Joint acceleration of a MoveJ at `acc` 100 % (deg/s²). FAIRINO publishes none; the twin's
/// choice: full speed in half a second.
pub const MOVE_J_FULL_ACC_DEG_S2: Joints = [360.0, 360.0, 360.0, 366.0, 366.0, 366.0];
