//! A small arm built only from meshes (binary STL, ASCII STL, OBJ, COLLADA), laid out like a ROS
//! package under tests/data/mesh_robot: `package://` resolution with and without package roots,
//! `file://` URIs, mesh contents and `scale`, and building it into a rapier world with either
//! mesh collision mode. The meshes come from tests/data/mesh_robot/generate_meshes.py.

use fairgrasp_sim::SimError;
use fairgrasp_sim::model::{
    Geometry, JointKind, LoadOptions, MeshCollision, PackagePaths, RobotModel, TriangleMesh,
};
use fairgrasp_sim::rapier3d::prelude::{
    ColliderSet, ImpulseJointSet, MultibodyJointSet, RigidBodySet, ShapeType,
};
use fairgrasp_sim::robot::{JointSets, Robot, RobotBuildOptions};
use std::path::{Path, PathBuf};

const PACKAGE: &str = "mesh_robot_description";

/// The directory holding the package, i.e. what a ROS_PACKAGE_PATH entry would name.
fn packages_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mesh_robot")
}

fn urdf_path() -> PathBuf {
    packages_dir().join(PACKAGE).join("urdf/arm.urdf")
}

fn with_roots(roots: Vec<PathBuf>) -> LoadOptions {
    LoadOptions {
        packages: PackagePaths { roots },
    }
}

fn load_with_root() -> RobotModel {
    RobotModel::load(urdf_path(), &with_roots(vec![packages_dir()]))
        .unwrap_or_else(|e| panic!("the mesh robot should load: {e}"))
}

/// The mesh, scale and resolved path of the first collision shape of `link`.
fn collision_mesh<'m>(model: &'m RobotModel, link: &str) -> (&'m TriangleMesh, [f64; 3], &'m Path) {
    let index = model
        .link_index(link)
        .unwrap_or_else(|| panic!("no link '{link}'"));
    match &model.links[index].collisions[0].geometry {
        Geometry::Mesh {
            mesh, scale, path, ..
        } => (mesh, *scale, path),
        other => panic!("link '{link}': expected a mesh collision, got {other:?}"),
    }
}

fn assert_bounds(mesh: &TriangleMesh, min: [f32; 3], max: [f32; 3], what: &str) {
    let (lo, hi) = mesh.bounds();
    for k in 0..3 {
        let tolerance = 1e-5 * (1.0 + max[k].abs().max(min[k].abs()));
        assert!(
            (lo[k] - min[k]).abs() <= tolerance && (hi[k] - max[k]).abs() <= tolerance,
            "{what}: bounds {lo:?}..{hi:?}, expected {min:?}..{max:?}"
        );
    }
}

#[test]
fn loads_with_package_root() {
    let model = load_with_root();
    assert_eq!(model.name, "mesh_robot");
    let links: Vec<&str> = model.links.iter().map(|l| l.name.as_str()).collect();
    assert_eq!(links, ["base_link", "link1", "link2", "gripper", "tool0"]);
    assert_eq!(model.links[model.root].name, "base_link");
    let joints: Vec<(&str, JointKind)> = model
        .joints
        .iter()
        .map(|j| (j.name.as_str(), j.kind))
        .collect();
    assert_eq!(
        joints,
        [
            ("joint1", JointKind::Revolute),
            ("joint2", JointKind::Revolute),
            ("joint3", JointKind::Revolute),
            ("tool0_joint", JointKind::Fixed),
        ]
    );
    assert_eq!(model.actuated_joints().len(), 3);
    assert_eq!(model.links[model.end_link()].name, "tool0");

    // Every link but tool0 has one mesh visual and one mesh collision, resolved into the package.
    let meshes_dir = packages_dir().join(PACKAGE).join("meshes");
    for link in model.links.iter().filter(|l| l.name != "tool0") {
        assert_eq!(link.visuals.len(), 1, "link '{}'", link.name);
        assert_eq!(link.collisions.len(), 1, "link '{}'", link.name);
        for shape in link.visuals.iter().chain(&link.collisions) {
            let Geometry::Mesh { uri, path, .. } = &shape.geometry else {
                panic!("link '{}': not a mesh", link.name);
            };
            assert!(
                uri.starts_with("package://mesh_robot_description/meshes/"),
                "{uri}"
            );
            assert_eq!(
                path.parent(),
                Some(meshes_dir.as_path()),
                "{uri} -> {}",
                path.display()
            );
        }
        assert!(
            link.visuals[0].rgba.is_some(),
            "link '{}' visual colour",
            link.name
        );
    }
    let link1 = &model.links[model.link_index("link1").unwrap()];
    assert_eq!(link1.visuals[0].rgba, Some([1.0, 0.5, 0.1, 1.0]));
}

#[test]
fn package_root_may_be_the_package_directory_itself() {
    let model = RobotModel::load(urdf_path(), &with_roots(vec![packages_dir().join(PACKAGE)]))
        .unwrap_or_else(|e| panic!("{e}"));
    let (_, _, path) = collision_mesh(&model, "gripper");
    assert_eq!(
        path,
        packages_dir().join(PACKAGE).join("meshes/gripper.dae")
    );
}

#[test]
fn loads_without_roots_by_walking_up_from_the_urdf() {
    let model = RobotModel::load(urdf_path(), &LoadOptions::default())
        .unwrap_or_else(|e| panic!("fallback resolution should find the package: {e}"));
    let (_, _, path) = collision_mesh(&model, "base_link");
    assert_eq!(path, packages_dir().join(PACKAGE).join("meshes/base.stl"));
}

#[test]
fn package_root_pointing_elsewhere_is_a_clear_error() {
    // A copy of the URDF away from its package, so walking up from it cannot find the meshes,
    // and a package root that does not hold the package.
    let temp = tempfile::tempdir().unwrap();
    let urdf_dir = temp.path().join("robots/urdf");
    std::fs::create_dir_all(&urdf_dir).unwrap();
    let copy = urdf_dir.join("arm.urdf");
    std::fs::copy(urdf_path(), &copy).unwrap();
    let wrong_root = temp.path().join("elsewhere");
    std::fs::create_dir_all(&wrong_root).unwrap();

    let err = RobotModel::load(&copy, &with_roots(vec![wrong_root.clone()]))
        .expect_err("the meshes cannot be found");
    assert!(matches!(err, SimError::Mesh { .. }), "{err:?}");
    let text = err.to_string();
    for fragment in [
        "link 'base_link' <collision> #1",
        "package://mesh_robot_description/meshes/base.stl",
        "package 'mesh_robot_description' not found",
        "searched 1 package root(s)",
        &wrong_root
            .join("mesh_robot_description/meshes/base.stl")
            .display()
            .to_string(),
    ] {
        assert!(text.contains(fragment), "error lacks {fragment:?}: {text}");
    }

    // The same copy loads once the right root is given.
    RobotModel::load(&copy, &with_roots(vec![wrong_root, packages_dir()]))
        .unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn binary_stl_has_expected_triangles_and_bounds() {
    let model = load_with_root();
    let (mesh, scale, path) = collision_mesh(&model, "base_link");
    let bytes = std::fs::read(path).unwrap();
    assert!(!bytes.starts_with(b"solid"), "base.stl should be binary");
    assert_eq!(bytes.len(), 84 + 50 * 92);
    assert_eq!(mesh.triangles.len(), 92);
    assert_eq!(scale, [1.0; 3]);
    assert_bounds(mesh, [-0.08, -0.08, 0.0], [0.08, 0.08, 0.1], "base.stl");
}

#[test]
fn ascii_stl_has_expected_triangles_and_bounds_before_scale() {
    let model = load_with_root();
    let (mesh, _, path) = collision_mesh(&model, "link1");
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.starts_with("solid link1"), "link1.stl should be ASCII");
    assert_eq!(mesh.triangles.len(), 12);
    // The file is in millimetres: the mesh keeps its own units, the URDF scale converts them.
    assert_bounds(mesh, [-30.0, -30.0, 0.0], [30.0, 30.0, 300.0], "link1.stl");
}

#[test]
fn obj_polygons_are_triangulated() {
    let model = load_with_root();
    let (mesh, _, _) = collision_mesh(&model, "link2");
    // 16 quads on the side (2 triangles each) and two 16-gon caps (14 triangles each).
    assert_eq!(mesh.triangles.len(), 16 * 2 + 2 * 14);
    assert_bounds(mesh, [-0.03, -0.03, 0.0], [0.03, 0.03, 0.25], "link2.obj");
    let n = mesh.vertices.len() as u32;
    assert!(mesh.triangles.iter().flatten().all(|&i| i < n));
}

#[test]
fn collada_mesh_has_expected_triangles_and_bounds() {
    let model = load_with_root();
    let (mesh, _, _) = collision_mesh(&model, "gripper");
    assert_eq!(mesh.triangles.len(), 28);
    assert_bounds(mesh, [-0.05, -0.02, 0.0], [0.05, 0.02, 0.08], "gripper.dae");
}

#[test]
fn mesh_scale_attribute_is_kept_and_applied_in_the_physics_shape() {
    let model = load_with_root();
    let (_, scale, _) = collision_mesh(&model, "link1");
    assert_eq!(scale, [0.001; 3]);
    let link1 = &model.links[model.link_index("link1").unwrap()];
    let Geometry::Mesh {
        scale: visual_scale,
        ..
    } = &link1.visuals[0].geometry
    else {
        panic!("link1 visual is not a mesh");
    };
    assert_eq!(*visual_scale, [0.001; 3]);

    // In the world the 60 x 60 x 300 mm box is a 0.06 x 0.06 x 0.3 m hull.
    let (robot, bodies, colliders) = build(model, MeshCollision::ConvexHull);
    let body = robot.link_body("link1").unwrap();
    let handles = bodies[body].colliders();
    assert_eq!(handles.len(), 1);
    let aabb = colliders[handles[0]].shape().compute_local_aabb();
    let extents = aabb.maxs - aabb.mins;
    for (k, expected) in [0.06f32, 0.06, 0.3].into_iter().enumerate() {
        assert!(
            (extents[k] - expected).abs() < 1e-5,
            "link1 collider extents {extents:?}, expected 0.06 x 0.06 x 0.3"
        );
    }
}

#[test]
fn file_uri_with_absolute_path_works() {
    let mesh = packages_dir().join(PACKAGE).join("meshes/link2.obj");
    assert!(mesh.is_absolute());
    let text = format!(
        r#"<?xml version="1.0"?>
<robot name="file_uri_robot">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <mass value="0.5"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>
    </inertial>
    <collision>
      <geometry>
        <mesh filename="file://{}" scale="2 2 2"/>
      </geometry>
    </collision>
  </link>
  <joint name="hinge" type="revolute">
    <parent link="base"/>
    <child link="arm"/>
    <axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="5" velocity="1"/>
  </joint>
</robot>
"#,
        mesh.display()
    );
    let temp = tempfile::tempdir().unwrap();
    let urdf = temp.path().join("file_uri.urdf");
    std::fs::write(&urdf, text).unwrap();

    let model = RobotModel::load(&urdf, &LoadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let (loaded, scale, path) = collision_mesh(&model, "arm");
    assert_eq!(path, mesh);
    assert_eq!(scale, [2.0; 3]);
    assert_eq!(loaded.triangles.len(), 60);

    // The same URI to a file that is not there names the path it tried.
    let missing = temp.path().join("missing.obj");
    let text = std::fs::read_to_string(&urdf)
        .unwrap()
        .replace(&mesh.display().to_string(), &missing.display().to_string());
    std::fs::write(&urdf, text).unwrap();
    let err = RobotModel::load(&urdf, &LoadOptions::default()).expect_err("missing mesh");
    let text = err.to_string();
    assert!(
        text.contains("link 'arm' <collision> #1")
            && text.contains(&format!("file not found: {}", missing.display())),
        "{text}"
    );
}

fn build(model: RobotModel, mode: MeshCollision) -> (Robot, RigidBodySet, ColliderSet) {
    let mut bodies = RigidBodySet::new();
    let mut colliders = ColliderSet::new();
    let mut multibody_joints = MultibodyJointSet::new();
    let mut impulse_joints = ImpulseJointSet::new();
    let options = RobotBuildOptions {
        mesh_collision: mode,
        ..RobotBuildOptions::default()
    };
    let robot = Robot::build(
        model,
        &options,
        &mut bodies,
        &mut colliders,
        JointSets {
            multibody_joints: &mut multibody_joints,
            impulse_joints: &mut impulse_joints,
        },
    )
    .unwrap_or_else(|e| panic!("building with {mode:?}: {e}"));
    (robot, bodies, colliders)
}

#[test]
fn builds_with_convex_hulls() {
    let (robot, bodies, colliders) = build(load_with_root(), MeshCollision::ConvexHull);
    // tool0 rides on the gripper's body; one collider per <collision>.
    assert_eq!(robot.bodies.len(), 4);
    assert_eq!(bodies.len(), 4);
    assert_eq!(colliders.len(), 4);
    let names: Vec<&str> = robot.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["joint1", "joint2", "joint3"]);
    for (_, collider) in colliders.iter() {
        assert_eq!(collider.shape().shape_type(), ShapeType::ConvexPolyhedron);
        assert!(collider.parent().is_some());
    }
    // The gripper's hull closes the U: it spans the full jaw.
    let gripper = robot.link_body("gripper").unwrap();
    let hull = colliders[bodies[gripper].colliders()[0]]
        .shape()
        .compute_local_aabb();
    let extents = hull.maxs - hull.mins;
    assert!(
        (extents.x - 0.1).abs() < 1e-5 && (extents.z - 0.08).abs() < 1e-5,
        "{extents:?}"
    );
}

#[test]
fn builds_with_convex_decomposition() {
    let (robot, bodies, colliders) = build(load_with_root(), MeshCollision::ConvexDecomposition);
    assert_eq!(robot.bodies.len(), 4);
    assert_eq!(colliders.len(), 4);
    for (_, collider) in colliders.iter() {
        let compound = collider.shape().as_compound().unwrap_or_else(|| {
            panic!(
                "expected a compound, got {:?}",
                collider.shape().shape_type()
            )
        });
        assert!(!compound.shapes().is_empty());
    }
    // The U-shaped jaw is concave: V-HACD needs more than one convex part for it.
    let gripper = robot.link_body("gripper").unwrap();
    let parts = colliders[bodies[gripper].colliders()[0]]
        .shape()
        .as_compound()
        .unwrap()
        .shapes()
        .len();
    assert!(
        parts >= 2,
        "the U-shaped jaw decomposed into {parts} part(s)"
    );
}
