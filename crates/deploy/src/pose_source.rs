//! Where the object's pose comes from on the real arm: a fixed pose, or JSON lines from the
//! user's perception over UDP or TCP.
//!
//! One message per line (UDP: one per datagram), positions in metres and orientation as a
//! unit quaternion, both in the **robot base frame**:
//!
//! ```json
//! {"position": [0.45, 0.02, 0.0225], "orientation_xyzw": [0, 0, 0, 1], "stamp": 12.5}
//! ```
//!
//! `orientation_xyzw` is optional (identity); `stamp` (seconds, the sender's clock) is
//! optional and only logged.

use serde::{Deserialize, Serialize};

/// One object pose message.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseMessage {
    /// Object centre in the robot base frame (m).
    pub position: [f64; 3],
    /// Unit quaternion x, y, z, w (identity when absent).
    #[serde(default = "identity")]
    pub orientation_xyzw: [f64; 4],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stamp: Option<f64>,
}

fn identity() -> [f64; 4] {
    [0.0, 0.0, 0.0, 1.0]
}
