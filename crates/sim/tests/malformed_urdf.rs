//! A corpus of broken robot descriptions (tests/data/malformed): each must be refused with an
//! error, never a panic, and the error must say what is wrong and where (the joint or link, the
//! element, or the line).

use fairgrasp_sim::model::{LoadOptions, RobotModel};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

/// (file in tests/data/malformed, fragments the error's text must contain).
const CASES: &[(&str, &[&str])] = &[
    // Not a URDF document at all.
    ("empty.urdf", &["line 1", "the file is empty"]),
    ("not_xml.urdf", &["line 1, column 1", "not well-formed XML"]),
    ("binary.urdf", &["cannot read", "valid UTF-8"]),
    (
        "truncated.urdf",
        &[
            "end of file (line 14)",
            "not well-formed XML",
            "unexpected end",
        ],
    ),
    ("dtd.urdf", &["not well-formed XML", "DTD"]),
    (
        "wrong_root.urdf",
        &["<sdf>", "root element must be <robot>"],
    ),
    // Xacro, found by content (a plain URDF that declares xmlns:xacro, or is named .xacro, loads).
    (
        "xacro_namespace.urdf",
        &[
            "line 4",
            "xacro element <xacro:property>",
            "this is xacro, not plain URDF",
            "expand it first",
        ],
    ),
    (
        "xacro_macro.urdf",
        &["line 5", "xacro element <xacro:macro>", "expand it first"],
    ),
    (
        "xacro_include.urdf.xacro",
        &["line 4", "xacro element <xacro:include>", "expand it first"],
    ),
    (
        "xacro_substitution.urdf",
        &[
            "line 12",
            "xacro substitution \"0 0 ${shoulder_height}\" in <origin xyz>",
        ],
    ),
    (
        "xacro_find.urdf",
        &[
            "line 12",
            "xacro substitution \"$(find broken_description)/meshes/arm.stl\" in <mesh filename>",
        ],
    ),
    (
        "xacro_other_prefix.urdf",
        &["line 5", "xacro element <xa:property>"],
    ),
    (
        "xacro_undeclared_prefix.urdf",
        &["line 6", "undeclared prefix `xacro:`", "expand it first"],
    ),
    // Joints.
    (
        "unknown_joint_type.urdf",
        &[
            "joint 'shoulder' (line 11)",
            "unknown joint type 'hinge'",
            "revolute",
        ],
    ),
    (
        "joint_missing_type.urdf",
        &["joint 'shoulder' (line 11)", "missing `type`"],
    ),
    (
        "missing_parent.urdf",
        &["joint 'shoulder' (line 11)", "missing <parent link="],
    ),
    (
        "missing_child.urdf",
        &["joint 'shoulder' (line 11)", "missing <child link="],
    ),
    (
        "undefined_parent_link.urdf",
        &["joint 'shoulder'", "parent link 'pedestal' is not defined"],
    ),
    (
        "undefined_child_link.urdf",
        &["joint 'elbow'", "child link 'forearm' is not defined"],
    ),
    (
        "self_joint.urdf",
        &["joint 'spin'", "parent and child are the same link 'arm'"],
    ),
    (
        "duplicate_joint.urdf",
        &["joint 'shoulder'", "defined twice"],
    ),
    (
        "nan_joint_origin.urdf",
        &["joint 'shoulder'", "origin xyz must be finite", "NaN"],
    ),
    (
        "short_vector.urdf",
        &[
            "joint 'shoulder' <origin> (line 12)",
            "`xyz` must be 3 numbers",
            "\"0 0.1\"",
        ],
    ),
    (
        "lower_above_upper.urdf",
        &["joint 'shoulder'", "limit lower 2 is above upper -2"],
    ),
    (
        "zero_axis.urdf",
        &["joint 'shoulder'", "axis has zero length"],
    ),
    (
        "zero_effort.urdf",
        &[
            "joint 'shoulder'",
            "effort and velocity must be positive",
            "effort 0",
        ],
    ),
    (
        "revolute_without_limit.urdf",
        &[
            "joint 'shoulder' (line 11)",
            "a revolute joint needs <limit",
        ],
    ),
    (
        "mimic_undefined.urdf",
        &[
            "joint 'finger_right_joint'",
            "mimics joint 'finger_middle_joint', which is not defined",
        ],
    ),
    (
        "floating_joint.urdf",
        &["joint 'free'", "Floating is not supported", "revolute"],
    ),
    (
        "planar_joint.urdf",
        &["joint 'slide'", "Planar is not supported"],
    ),
    // The tree.
    (
        "kinematic_loop.urdf",
        &[
            "link 'link_a'",
            "kinematic loop",
            "URDF must describe a tree",
        ],
    ),
    (
        "two_parents.urdf",
        &[
            "link 'arm'",
            "child of two joints",
            "'shoulder'",
            "'column_to_arm'",
        ],
    ),
    (
        "two_roots.urdf",
        &[
            "2 links have no parent joint",
            "'base'",
            "'island'",
            "one connected tree",
        ],
    ),
    ("duplicate_link.urdf", &["link 'arm'", "defined twice"]),
    // Links: inertials and shapes.
    (
        "nan_inertial_origin.urdf",
        &["link 'arm' <inertial>", "origin xyz must be finite", "NaN"],
    ),
    (
        "inf_origin_rpy.urdf",
        &["link 'arm' <visual> #1", "origin rpy must be finite", "inf"],
    ),
    (
        "zero_mass_moving_link.urdf",
        &["link 'arm'", "zero mass", "revolute joint 'shoulder'"],
    ),
    (
        "negative_mass.urdf",
        &["link 'arm'", "mass must be positive, got -2.5"],
    ),
    (
        "negative_inertia.urdf",
        &["link 'arm'", "must not be negative", "-0.02"],
    ),
    (
        "missing_mass_value.urdf",
        &["link 'arm' <mass> (line 7)", "missing `value`"],
    ),
    (
        "negative_box.urdf",
        &[
            "link 'arm' <collision> #1",
            "box size must be positive",
            "-0.1",
        ],
    ),
    // Mesh references.
    (
        "missing_mesh.urdf",
        &[
            "link 'arm' <collision> #1",
            "mesh 'meshes/does_not_exist.stl'",
            "file not found",
        ],
    ),
    (
        "unknown_package.urdf",
        &[
            "link 'arm' <visual> #1",
            "package://no_such_description/meshes/arm.stl",
            "package 'no_such_description' not found",
            "ROS_PACKAGE_PATH",
        ],
    ),
    (
        "package_without_path.urdf",
        &[
            "link 'arm' <collision> #1",
            "has no path after the package name",
        ],
    ),
    (
        "http_uri.urdf",
        &[
            "link 'arm' <collision> #1",
            "unsupported URI scheme",
            "http://example.com",
        ],
    ),
    // Mesh files.
    (
        "garbage_mesh.urdf",
        &[
            "link 'arm' <collision> #1",
            "garbage.stl is not a readable mesh",
            "binary STL",
        ],
    ),
    (
        "truncated_stl.urdf",
        &[
            "link 'arm' <collision> #1",
            "truncated.stl is not a readable mesh",
            "binary STL",
        ],
    ),
    (
        "truncated_stl_whole_triangles.urdf",
        &[
            "link 'arm' <collision> #1",
            "short_count.stl is truncated",
            "declares 4 triangles",
            "holds only 2",
        ],
    ),
    (
        "empty_stl.urdf",
        &[
            "link 'arm' <collision> #1",
            "empty.stl is not a readable mesh",
            "too small",
        ],
    ),
    (
        "stl_without_triangles.urdf",
        &[
            "link 'arm' <collision> #1",
            "no_triangles.stl contains no triangles",
        ],
    ),
    (
        "nan_vertex_stl.urdf",
        &[
            "link 'arm' <collision> #1",
            "nan_vertex.stl has non-finite vertex coordinates",
        ],
    ),
    (
        "lfs_pointer_mesh.urdf",
        &[
            "link 'arm' <collision> #1",
            "lfs_pointer.stl is a Git LFS pointer",
            "git lfs pull",
        ],
    ),
    (
        "unsupported_mesh_ext.urdf",
        &[
            "link 'arm' <collision> #1",
            "part.ply has an unsupported mesh format ('.ply')",
            "STL",
        ],
    ),
    (
        "obj_bad_index.urdf",
        &[
            "link 'arm' <collision> #1",
            "bad_index.obj is not a readable mesh",
            "out of bounds",
        ],
    ),
    (
        "garbage_obj.urdf",
        &[
            "link 'arm' <collision> #1",
            "text.obj contains no triangles",
        ],
    ),
    (
        "broken_collada.urdf",
        &[
            "link 'arm' <collision> #1",
            "not_collada.dae is not a readable mesh",
            "never closed",
        ],
    ),
];

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/malformed")
}

#[test]
fn every_malformed_file_is_refused_with_a_precise_error() {
    let mut failures = Vec::new();
    for &(file, fragments) in CASES {
        let path = corpus_dir().join(file);
        assert!(path.is_file(), "corpus file {} is missing", path.display());
        let outcome = catch_unwind(AssertUnwindSafe(|| {
            RobotModel::load(&path, &LoadOptions::default())
        }));
        let message = match outcome {
            Err(_) => {
                failures.push(format!("{file}: panicked"));
                continue;
            }
            Ok(Ok(model)) => {
                failures.push(format!(
                    "{file}: loaded a robot '{}' instead of failing",
                    model.name
                ));
                continue;
            }
            Ok(Err(err)) => err.to_string(),
        };
        // Every error names the file it is about, then the specific fragments.
        let missing: Vec<&str> = std::iter::once(file)
            .chain(fragments.iter().copied())
            .filter(|fragment| !message.contains(fragment))
            .collect();
        if !missing.is_empty() {
            failures.push(format!(
                "{file}: error lacks {missing:?}\n    error: {message}"
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} case(s) failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// Every description in the corpus has a row in the table, so none is silently skipped.
#[test]
fn every_corpus_file_has_a_case() {
    let mut unlisted = Vec::new();
    for entry in std::fs::read_dir(corpus_dir()).unwrap() {
        let path = entry.unwrap().path();
        if !path.is_file() {
            continue; // meshes/ holds the broken mesh files the descriptions point at
        }
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if !CASES.iter().any(|(file, _)| *file == name) {
            unlisted.push(name);
        }
    }
    unlisted.sort();
    assert!(
        unlisted.is_empty(),
        "corpus files without a case: {unlisted:?}"
    );
    let mut names: Vec<&str> = CASES.iter().map(|(file, _)| *file).collect();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), CASES.len(), "a file is listed twice");
}

/// The corpus files are a small valid arm with one defect each; the arm itself loads, so each
/// failure above is due to its defect.
#[test]
fn the_arm_the_corpus_is_made_from_is_valid() {
    let text = r#"<?xml version="1.0"?>
<robot name="broken_arm">
  <link name="base"/>
  <link name="arm">
    <inertial>
      <mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
    <collision>
      <origin xyz="0 0 0.15" rpy="0 0 0"/>
      <geometry>
        <box size="0.1 0.1 0.3"/>
      </geometry>
    </collision>
  </link>
  <joint name="shoulder" type="revolute">
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <parent link="base"/>
    <child link="arm"/>
    <axis xyz="0 0 1"/>
    <limit lower="-1.57" upper="1.57" effort="20" velocity="2"/>
  </joint>
</robot>
"#;
    let model =
        RobotModel::from_urdf_str(text, "control.urdf", &corpus_dir(), &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.links.len(), 2);
    assert_eq!(model.joints.len(), 1);
}
