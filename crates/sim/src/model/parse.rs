//! URDF text → [`RobotModel`], with errors that name the element at fault.
//!
//! urdf-rs does the deserialisation. Before it, roxmltree checks that the text is well-formed XML,
//! holds no xacro, and that every joint has a known type, because those failures would otherwise
//! surface as serde messages without a line number or joint name.

use super::{
    Geometry, Inertial, Joint, JointKind, JointLimits, Link, LoadOptions, Mimic, Origin,
    RobotModel, Shape, mesh, packages, xacro,
};
use crate::error::{Result, SimError};
use std::collections::HashMap;
use std::path::Path;

const JOINT_TYPES: [&str; 6] = [
    "revolute",
    "continuous",
    "prismatic",
    "fixed",
    "floating",
    "planar",
];

pub(super) fn parse_urdf(
    text: &str,
    source_name: &str,
    base_dir: &Path,
    options: &LoadOptions,
) -> Result<RobotModel> {
    precheck_xml(text, source_name)?;
    let robot = urdf_rs::read_from_string(text).map_err(|e| {
        SimError::urdf(
            source_name,
            "robot",
            format!("not a valid URDF document: {e}"),
        )
    })?;
    build_model(&robot, source_name, base_dir, options)
}

/// Well-formedness, xacro, joint types and numeric attributes, reported with line and column.
fn precheck_xml(text: &str, source_name: &str) -> Result<()> {
    if text.trim().is_empty() {
        return Err(SimError::urdf(source_name, "line 1", "the file is empty"));
    }
    let xacro_error = |line: u32, found: String| SimError::Xacro {
        source_name: source_name.to_string(),
        line,
        found,
    };
    let doc = roxmltree::Document::parse(text).map_err(|e| {
        let location = match e {
            // xacro itself accepts `<xacro:…>` without a namespace declaration.
            roxmltree::Error::UnknownNamespace(ref prefix, pos) if prefix == "xacro" => {
                return xacro_error(pos.row, "undeclared prefix `xacro:`".to_string());
            }
            // roxmltree gives these no position (it reports 1:1); the problem is at the end.
            roxmltree::Error::UnexpectedEndOfStream | roxmltree::Error::UnclosedRootNode => {
                format!("end of file (line {})", text.lines().count().max(1))
            }
            _ => format!("line {}, column {}", e.pos().row, e.pos().col),
        };
        SimError::urdf(source_name, location, format!("not well-formed XML: {e}"))
    })?;
    if let Some((line, found)) = xacro::first_xacro_construct(&doc) {
        return Err(xacro_error(line, found));
    }
    let root = doc.root_element();
    if root.tag_name().name() != "robot" {
        return Err(SimError::urdf(
            source_name,
            format!("<{}>", root.tag_name().name()),
            "the root element must be <robot>",
        ));
    }
    for joint in root.children().filter(|n| n.has_tag_name("joint")) {
        let pos = doc.text_pos_at(joint.range().start);
        let Some(name) = joint.attribute("name") else {
            return Err(SimError::urdf(
                source_name,
                format!("joint at line {}", pos.row),
                "missing `name`",
            ));
        };
        let location = format!("joint '{name}' (line {})", pos.row);
        match joint.attribute("type") {
            None => return Err(SimError::urdf(source_name, location, "missing `type`")),
            Some(t) if !JOINT_TYPES.contains(&t) => {
                return Err(SimError::urdf(
                    source_name,
                    location,
                    format!(
                        "unknown joint type '{t}'; expected one of {}",
                        JOINT_TYPES.join(", ")
                    ),
                ));
            }
            // urdf-rs would fill in a zero limit, reported later as a confusing "effort 0".
            Some(t @ ("revolute" | "prismatic"))
                if !joint.children().any(|c| c.has_tag_name("limit")) =>
            {
                return Err(SimError::urdf(
                    source_name,
                    location,
                    format!("a {t} joint needs <limit effort=\"…\" velocity=\"…\"/>"),
                ));
            }
            Some(_) => {}
        }
        for tag in ["parent", "child"] {
            let has_link = joint
                .children()
                .any(|c| c.has_tag_name(tag) && c.attribute("link").is_some());
            if !has_link {
                return Err(SimError::urdf(
                    source_name,
                    location,
                    format!("missing <{tag} link=\"…\"/>"),
                ));
            }
        }
    }
    for link in root.children().filter(|n| n.has_tag_name("link")) {
        if link.attribute("name").is_none() {
            let pos = doc.text_pos_at(link.range().start);
            return Err(SimError::urdf(
                source_name,
                format!("link at line {}", pos.row),
                "missing `name`",
            ));
        }
    }
    check_attributes(&doc, source_name)
}

/// Attributes urdf-rs reads as numbers: (element, attribute, how many numbers, required).
/// `0` numbers means any text. urdf-rs reports these without saying where they are.
const ATTRIBUTES: &[(&str, &str, usize, bool)] = &[
    ("origin", "xyz", 3, false),
    ("origin", "rpy", 3, false),
    ("axis", "xyz", 3, true),
    ("mass", "value", 1, true),
    ("inertia", "ixx", 1, true),
    ("inertia", "ixy", 1, true),
    ("inertia", "ixz", 1, true),
    ("inertia", "iyy", 1, true),
    ("inertia", "iyz", 1, true),
    ("inertia", "izz", 1, true),
    ("box", "size", 3, true),
    ("cylinder", "radius", 1, true),
    ("cylinder", "length", 1, true),
    ("capsule", "radius", 1, true),
    ("capsule", "length", 1, true),
    ("sphere", "radius", 1, true),
    ("mesh", "filename", 0, true),
    ("mesh", "scale", 3, false),
    ("limit", "lower", 1, false),
    ("limit", "upper", 1, false),
    ("limit", "effort", 1, false),
    ("limit", "velocity", 1, true),
    ("dynamics", "damping", 1, false),
    ("dynamics", "friction", 1, false),
    ("mimic", "joint", 0, true),
    ("mimic", "multiplier", 1, false),
    ("mimic", "offset", 1, false),
    ("color", "rgba", 4, true),
];

/// Missing or malformed attributes inside the links, joints and materials urdf-rs reads,
/// named by their owner, element and line.
fn check_attributes(doc: &roxmltree::Document, source_name: &str) -> Result<()> {
    for owner in doc.root_element().children().filter(|n| n.is_element()) {
        let kind = owner.tag_name().name();
        if !matches!(kind, "link" | "joint" | "material") {
            continue;
        }
        let owner_name = owner.attribute("name").unwrap_or("?");
        // Of a link, urdf-rs reads only these parts; other children (e.g. extensions) are free.
        let parts = owner.children().filter(|n| {
            n.is_element()
                && (kind != "link"
                    || ["inertial", "visual", "collision"].contains(&n.tag_name().name()))
        });
        for element in parts
            .flat_map(|p| p.descendants())
            .filter(|n| n.is_element())
        {
            let tag = element.tag_name().name();
            for &(_, attribute, count, required) in ATTRIBUTES.iter().filter(|a| a.0 == tag) {
                let problem = match element.attribute(attribute) {
                    None if required => format!("missing `{attribute}`"),
                    Some(value) if count > 0 => {
                        let numbers: Vec<&str> = value.split_whitespace().collect();
                        if numbers.len() == count
                            && numbers.iter().all(|v| v.parse::<f64>().is_ok())
                        {
                            continue;
                        }
                        let expected = if count == 1 {
                            "a number".to_string()
                        } else {
                            format!("{count} numbers separated by spaces")
                        };
                        format!("`{attribute}` must be {expected}, got \"{value}\"")
                    }
                    _ => continue,
                };
                let pos = doc.text_pos_at(element.range().start);
                return Err(SimError::urdf(
                    source_name,
                    format!("{kind} '{owner_name}' <{tag}> (line {})", pos.row),
                    problem,
                ));
            }
        }
    }
    Ok(())
}

fn origin(pose: &urdf_rs::Pose) -> Origin {
    Origin {
        xyz: pose.xyz.0,
        rpy: pose.rpy.0,
    }
}

fn check_finite(values: &[f64], source_name: &str, location: &str, what: &str) -> Result<()> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(SimError::urdf(
            source_name,
            location,
            format!("{what} must be finite numbers, got {values:?}"),
        ))
    }
}

fn check_origin(o: &Origin, source_name: &str, location: &str) -> Result<()> {
    check_finite(&o.xyz, source_name, location, "origin xyz")?;
    check_finite(&o.rpy, source_name, location, "origin rpy")
}

fn build_model(
    robot: &urdf_rs::Robot,
    source_name: &str,
    base_dir: &Path,
    options: &LoadOptions,
) -> Result<RobotModel> {
    if robot.links.is_empty() {
        return Err(SimError::urdf(source_name, "robot", "has no <link>"));
    }
    let mut link_index = HashMap::new();
    for (i, link) in robot.links.iter().enumerate() {
        if link_index.insert(link.name.as_str(), i).is_some() {
            return Err(SimError::urdf(
                source_name,
                format!("link '{}'", link.name),
                "defined twice",
            ));
        }
    }
    let materials: HashMap<&str, [f64; 4]> = robot
        .materials
        .iter()
        .filter_map(|m| m.color.as_ref().map(|c| (m.name.as_str(), c.rgba.0)))
        .collect();

    let mut links = Vec::with_capacity(robot.links.len());
    for link in &robot.links {
        let location = format!("link '{}'", link.name);
        let i = &link.inertial;
        let inertia = [
            i.inertia.ixx,
            i.inertia.ixy,
            i.inertia.ixz,
            i.inertia.iyy,
            i.inertia.iyz,
            i.inertia.izz,
        ];
        check_finite(&[i.mass.value], source_name, &location, "mass")?;
        check_finite(&inertia, source_name, &location, "inertia")?;
        check_origin(
            &origin(&i.origin),
            source_name,
            &format!("{location} <inertial>"),
        )?;
        if i.mass.value < 0.0 {
            return Err(SimError::urdf(
                source_name,
                location,
                format!("mass must be positive, got {}", i.mass.value),
            ));
        }
        if inertia[0] < 0.0 || inertia[3] < 0.0 || inertia[5] < 0.0 {
            return Err(SimError::urdf(
                source_name,
                location,
                format!("principal moments ixx, iyy, izz must not be negative, got {inertia:?}"),
            ));
        }
        let inertial = (i.mass.value > 0.0).then(|| Inertial {
            origin: origin(&i.origin),
            mass: i.mass.value,
            inertia,
        });
        let mut collisions = Vec::new();
        for (k, c) in link.collision.iter().enumerate() {
            let loc = format!("{location} <collision> #{}", k + 1);
            collisions.push(shape(
                &c.geometry,
                origin(&c.origin),
                None,
                source_name,
                &loc,
                base_dir,
                options,
            )?);
        }
        let mut visuals = Vec::new();
        for (k, v) in link.visual.iter().enumerate() {
            let loc = format!("{location} <visual> #{}", k + 1);
            let rgba = v.material.as_ref().and_then(|m| {
                m.color
                    .as_ref()
                    .map(|c| c.rgba.0)
                    .or_else(|| materials.get(m.name.as_str()).copied())
            });
            visuals.push(shape(
                &v.geometry,
                origin(&v.origin),
                rgba,
                source_name,
                &loc,
                base_dir,
                options,
            )?);
        }
        links.push(Link {
            name: link.name.clone(),
            inertial,
            collisions,
            visuals,
        });
    }

    let mut joint_index = HashMap::new();
    for (i, joint) in robot.joints.iter().enumerate() {
        if joint_index.insert(joint.name.as_str(), i).is_some() {
            return Err(SimError::urdf(
                source_name,
                format!("joint '{}'", joint.name),
                "defined twice",
            ));
        }
    }
    let mut joints = Vec::with_capacity(robot.joints.len());
    for joint in &robot.joints {
        joints.push(convert_joint(
            joint,
            &link_index,
            &joint_index,
            &links,
            source_name,
        )?);
    }

    let root = check_tree(&links, &joints, source_name)?;
    let joints = sort_root_to_leaves(joints, root, links.len());
    // Mimic indices referred to the original joint order; re-map them by name.
    let names: Vec<String> = joints.iter().map(|j| j.name.clone()).collect();
    let joints = joints
        .into_iter()
        .map(|mut j| {
            if let Some(m) = &mut j.mimic {
                let target = &robot.joints[m.joint].name;
                m.joint = names.iter().position(|n| n == target).unwrap_or(m.joint);
            }
            j
        })
        .collect();

    Ok(RobotModel {
        name: robot.name.clone(),
        source_name: source_name.to_string(),
        links,
        joints,
        root,
    })
}

fn convert_joint(
    joint: &urdf_rs::Joint,
    link_index: &HashMap<&str, usize>,
    joint_index: &HashMap<&str, usize>,
    links: &[Link],
    source_name: &str,
) -> Result<Joint> {
    let location = format!("joint '{}'", joint.name);
    let kind = match &joint.joint_type {
        urdf_rs::JointType::Revolute => JointKind::Revolute,
        urdf_rs::JointType::Continuous => JointKind::Continuous,
        urdf_rs::JointType::Prismatic => JointKind::Prismatic,
        urdf_rs::JointType::Fixed => JointKind::Fixed,
        other => {
            return Err(SimError::urdf(
                source_name,
                location,
                format!(
                    "joint type {other:?} is not supported for arms and grippers; \
                     use revolute, continuous, prismatic or fixed"
                ),
            ));
        }
    };
    let find_link = |name: &str, role: &str| {
        link_index.get(name).copied().ok_or_else(|| {
            SimError::urdf(
                source_name,
                location.clone(),
                format!("{role} link '{name}' is not defined"),
            )
        })
    };
    let parent = find_link(&joint.parent.link, "parent")?;
    let child = find_link(&joint.child.link, "child")?;
    if parent == child {
        return Err(SimError::urdf(
            source_name,
            location,
            format!("parent and child are the same link '{}'", joint.parent.link),
        ));
    }
    let origin = origin(&joint.origin);
    check_origin(&origin, source_name, &location)?;
    let raw_axis = joint.axis.xyz.0;
    check_finite(&raw_axis, source_name, &location, "axis")?;
    let norm = raw_axis.iter().map(|v| v * v).sum::<f64>().sqrt();
    if kind.is_movable() && norm < 1e-9 {
        return Err(SimError::urdf(
            source_name,
            location,
            "axis has zero length",
        ));
    }
    let axis = if norm < 1e-9 {
        [1.0, 0.0, 0.0]
    } else {
        raw_axis.map(|v| v / norm)
    };
    let l = &joint.limit;
    check_finite(
        &[l.lower, l.upper, l.effort, l.velocity],
        source_name,
        &location,
        "limit values",
    )?;
    let limits = match kind {
        JointKind::Revolute | JointKind::Prismatic => {
            if l.lower > l.upper {
                return Err(SimError::urdf(
                    source_name,
                    location,
                    format!("limit lower {} is above upper {}", l.lower, l.upper),
                ));
            }
            if l.effort <= 0.0 || l.velocity <= 0.0 {
                return Err(SimError::urdf(
                    source_name,
                    location,
                    format!(
                        "limit effort and velocity must be positive, got effort {} velocity {}",
                        l.effort, l.velocity
                    ),
                ));
            }
            Some(JointLimits {
                lower: l.lower,
                upper: l.upper,
                effort: l.effort,
                velocity: l.velocity,
            })
        }
        JointKind::Continuous if l.effort > 0.0 && l.velocity > 0.0 => Some(JointLimits {
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            effort: l.effort,
            velocity: l.velocity,
        }),
        _ => None,
    };
    let (damping, friction) = joint
        .dynamics
        .as_ref()
        .map(|d| (d.damping, d.friction))
        .unwrap_or((0.0, 0.0));
    check_finite(&[damping, friction], source_name, &location, "dynamics")?;
    if damping < 0.0 || friction < 0.0 {
        return Err(SimError::urdf(
            source_name,
            location,
            "dynamics damping and friction must not be negative",
        ));
    }
    let mimic = match &joint.mimic {
        None => None,
        Some(m) => {
            let target = joint_index.get(m.joint.as_str()).copied().ok_or_else(|| {
                SimError::urdf(
                    source_name,
                    location.clone(),
                    format!("mimics joint '{}', which is not defined", m.joint),
                )
            })?;
            let multiplier = m.multiplier.unwrap_or(1.0);
            let offset = m.offset.unwrap_or(0.0);
            check_finite(&[multiplier, offset], source_name, &location, "mimic")?;
            Some(Mimic {
                joint: target,
                multiplier,
                offset,
            })
        }
    };
    if kind.is_movable() && links[child].inertial.is_none() {
        return Err(SimError::urdf(
            source_name,
            format!("link '{}'", links[child].name),
            format!(
                "has zero mass but is moved by {kind} joint '{}'; a moving link needs a positive mass",
                joint.name,
                kind = kind.as_str()
            ),
        ));
    }
    Ok(Joint {
        name: joint.name.clone(),
        kind,
        parent,
        child,
        origin,
        axis,
        limits,
        damping,
        friction,
        mimic,
    })
}

/// Every link has at most one parent, there is exactly one root, and no cycle.
fn check_tree(links: &[Link], joints: &[Joint], source_name: &str) -> Result<usize> {
    let mut parent_of: Vec<Option<usize>> = vec![None; links.len()];
    for (j, joint) in joints.iter().enumerate() {
        if let Some(previous) = parent_of[joint.child] {
            return Err(SimError::urdf(
                source_name,
                format!("link '{}'", links[joint.child].name),
                format!(
                    "is the child of two joints, '{}' and '{}'",
                    joints[previous].name, joint.name
                ),
            ));
        }
        parent_of[joint.child] = Some(j);
    }
    // A cycle: walking up from a link comes back to it.
    for start in 0..links.len() {
        let mut current = start;
        for _ in 0..=links.len() {
            match parent_of[current] {
                Some(j) => current = joints[j].parent,
                None => break,
            }
            if current == start {
                return Err(SimError::urdf(
                    source_name,
                    format!("link '{}'", links[start].name),
                    "is part of a kinematic loop; URDF must describe a tree",
                ));
            }
        }
    }
    let roots: Vec<usize> = (0..links.len())
        .filter(|&l| parent_of[l].is_none())
        .collect();
    match roots.as_slice() {
        [root] => Ok(*root),
        [] => Err(SimError::urdf(
            source_name,
            "robot",
            "no root link (every link has a parent joint)",
        )),
        many => Err(SimError::urdf(
            source_name,
            "robot",
            format!(
                "{} links have no parent joint ({}); the links must form one connected tree",
                many.len(),
                many.iter()
                    .map(|&l| format!("'{}'", links[l].name))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

fn sort_root_to_leaves(joints: Vec<Joint>, root: usize, n_links: usize) -> Vec<Joint> {
    let mut placed = vec![false; n_links];
    placed[root] = true;
    let mut remaining = joints;
    let mut sorted = Vec::with_capacity(remaining.len());
    while !remaining.is_empty() {
        let (ready, rest): (Vec<Joint>, Vec<Joint>) =
            remaining.into_iter().partition(|j| placed[j.parent]);
        if ready.is_empty() {
            // Unreachable after `check_tree`; keep the rest in file order rather than loop.
            sorted.extend(rest);
            break;
        }
        for j in &ready {
            placed[j.child] = true;
        }
        sorted.extend(ready);
        remaining = rest;
    }
    sorted
}

fn shape(
    geometry: &urdf_rs::Geometry,
    origin: Origin,
    rgba: Option<[f64; 4]>,
    source_name: &str,
    location: &str,
    base_dir: &Path,
    options: &LoadOptions,
) -> Result<Shape> {
    check_origin(&origin, source_name, location)?;
    let positive = |values: &[f64], what: &str| -> Result<()> {
        if values.iter().all(|v| v.is_finite() && *v > 0.0) {
            Ok(())
        } else {
            Err(SimError::urdf(
                source_name,
                location,
                format!("{what} must be positive finite numbers, got {values:?}"),
            ))
        }
    };
    let geometry = match geometry {
        urdf_rs::Geometry::Box { size } => {
            positive(&size.0, "box size")?;
            Geometry::Box { size: size.0 }
        }
        urdf_rs::Geometry::Cylinder { radius, length } => {
            positive(&[*radius, *length], "cylinder radius and length")?;
            Geometry::Cylinder {
                radius: *radius,
                length: *length,
            }
        }
        urdf_rs::Geometry::Capsule { radius, length } => {
            positive(&[*radius], "capsule radius")?;
            check_finite(&[*length], source_name, location, "capsule length")?;
            Geometry::Capsule {
                radius: *radius,
                length: length.max(0.0),
            }
        }
        urdf_rs::Geometry::Sphere { radius } => {
            positive(&[*radius], "sphere radius")?;
            Geometry::Sphere { radius: *radius }
        }
        urdf_rs::Geometry::Mesh { filename, scale } => {
            let scale = scale.map(|s| s.0).unwrap_or([1.0; 3]);
            positive(&scale, "mesh scale")?;
            let path = packages::resolve_uri(filename, base_dir, &options.packages).map_err(
                |problem| SimError::Mesh {
                    source_name: source_name.to_string(),
                    location: location.to_string(),
                    uri: filename.clone(),
                    problem,
                },
            )?;
            let mesh = mesh::load_mesh(&path).map_err(|problem| SimError::Mesh {
                source_name: source_name.to_string(),
                location: location.to_string(),
                uri: filename.clone(),
                problem,
            })?;
            Geometry::Mesh {
                uri: filename.clone(),
                path,
                scale,
                mesh,
            }
        }
    };
    Ok(Shape {
        origin,
        geometry,
        rgba,
    })
}
