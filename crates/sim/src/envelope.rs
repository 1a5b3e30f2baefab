//! The arm's envelope: spheres covering every collision shape the arm carries, placed by
//! forward kinematics, for clearance checks against the table and the cell's walls.
//!
//! A capsule or cylinder is covered by the spheres at the two ends of its axis, a box or mesh
//! by the corners of its bounding box (spheres of radius 0), a sphere by itself. The checks
//! this serves are half-spaces and boxes, which are convex: a shape lies inside when the
//! spheres covering its convex hull do, so a check of a few points per shape is exact or
//! errs on the safe side. Links off the chain (the fingers) are covered at both ends of a
//! prismatic joint's travel (a translated convex shape stays inside when both ends do) and
//! by one sphere about a revolute joint's origin reaching their farthest point.
//!
//! The base and the link the first joint turns are left out: they stand on the mount, and
//! the table they stand on is what the others are kept from.

use crate::error::{Result, SimError};
use crate::kinematics::{SerialChain, origin_to_isometry};
use crate::model::{Geometry, JointKind, RobotModel, Shape};
use rapier3d::na::{Isometry3, Point3, Vector3};

/// A sphere of the envelope in its link's frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre in the link's frame (m).
    pub centre: Point3<f64>,
    /// Radius (m); 0 for a corner of a box's or mesh's bounding box.
    pub radius: f64,
}

/// The spheres riding on one link of the chain.
#[derive(Clone, Debug)]
struct LinkSpheres {
    /// The chain link's name (the fingers' spheres ride on the link they hang from, under the
    /// finger's own name).
    part: String,
    spheres: Vec<Sphere>,
}

/// Spheres covering the arm's collision shapes from its second link to the tip (see the
/// [module](self) documentation).
#[derive(Clone, Debug)]
pub struct Envelope {
    chain: SerialChain,
    /// Per link of the chain, root to tip: the parts riding on it.
    links: Vec<Vec<LinkSpheres>>,
}

impl Envelope {
    /// The envelope of `model`'s chain from its root to the link `tip`.
    pub fn new(model: &RobotModel, tip: &str) -> Result<Self> {
        let chain = SerialChain::new(model, tip)?;
        let chain_links = chain.links();
        let first_moving = model
            .chain_to(*chain_links.last().unwrap_or(&model.root))
            .iter()
            .position(|&j| model.joints[j].kind.is_movable())
            .ok_or_else(|| {
                SimError::urdf(
                    &model.source_name,
                    format!("link '{tip}'"),
                    "no joint moves it",
                )
            })?;
        let mut links = Vec::with_capacity(chain_links.len());
        for (k, &link) in chain_links.iter().enumerate() {
            let mut parts = Vec::new();
            if k > first_moving {
                let own = shape_spheres(model, link, &Isometry3::identity());
                if !own.is_empty() {
                    parts.push(LinkSpheres {
                        part: model.links[link].name.clone(),
                        spheres: own,
                    });
                }
                for j in off_chain_children(model, link, &chain_links) {
                    let joint = &model.joints[j];
                    let spheres = subtree_spheres(model, j, &origin_to_isometry(&joint.origin))?;
                    if !spheres.is_empty() {
                        parts.push(LinkSpheres {
                            part: model.links[joint.child].name.clone(),
                            spheres,
                        });
                    }
                }
            }
            links.push(parts);
        }
        Ok(Self { chain, links })
    }

    /// The chain the envelope rides on (its joint vector is the envelope's).
    pub fn chain(&self) -> &SerialChain {
        &self.chain
    }

    /// Number of spheres.
    pub fn len(&self) -> usize {
        self.links.iter().flatten().map(|p| p.spheres.len()).sum()
    }

    /// Whether the envelope has no sphere: no link it covers carries a collision shape.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Places every sphere at joint vector `q` (root frame) and calls `check` with its centre
    /// and radius; stops at the first sphere `check` refuses and returns its part and centre.
    pub fn first_outside(
        &self,
        q: &[f64],
        mut check: impl FnMut(&Point3<f64>, f64) -> bool,
    ) -> Option<(&str, Point3<f64>)> {
        let mut found = None;
        let mut k = 0;
        self.chain.for_each_link(q, |_, pose| {
            if found.is_none() {
                for part in &self.links[k] {
                    for s in &part.spheres {
                        let centre = pose * s.centre;
                        if !check(&centre, s.radius) {
                            found = Some((part.part.as_str(), centre));
                            break;
                        }
                    }
                    if found.is_some() {
                        break;
                    }
                }
            }
            k += 1;
        });
        found
    }
}

/// Joints from `link` to links that are not on the chain.
fn off_chain_children<'a>(
    model: &'a RobotModel,
    link: usize,
    chain_links: &'a [usize],
) -> impl Iterator<Item = usize> + 'a {
    (0..model.joints.len()).filter(move |&j| {
        model.joints[j].parent == link && !chain_links.contains(&model.joints[j].child)
    })
}

/// The spheres of the subtree below joint `j`, in the frame `at` of its parent link (`at`:
/// the joint's origin in that frame).
fn subtree_spheres(model: &RobotModel, j: usize, at: &Isometry3<f64>) -> Result<Vec<Sphere>> {
    let joint = &model.joints[j];
    let below = |pose: &Isometry3<f64>| -> Result<Vec<Sphere>> {
        let mut out = shape_spheres(model, joint.child, pose);
        for c in (0..model.joints.len()).filter(|&c| model.joints[c].parent == joint.child) {
            out.extend(subtree_spheres(
                model,
                c,
                &(pose * origin_to_isometry(&model.joints[c].origin)),
            )?);
        }
        Ok(out)
    };
    match joint.kind {
        JointKind::Fixed => below(at),
        JointKind::Prismatic => {
            let limits = joint.limits.ok_or_else(|| {
                SimError::urdf(
                    &model.source_name,
                    format!("joint '{}'", joint.name),
                    "a prismatic joint needs limits to bound the envelope",
                )
            })?;
            let axis = Vector3::from(joint.axis);
            let mut out = Vec::new();
            for travel in [limits.lower, limits.upper] {
                out.extend(below(
                    &(at * Isometry3::translation(
                        axis.x * travel,
                        axis.y * travel,
                        axis.z * travel,
                    )),
                )?);
            }
            Ok(out)
        }
        _ => {
            // Any rotation about the joint keeps the subtree within its farthest point's
            // distance from the joint's origin.
            let reach = below(&Isometry3::identity())?
                .iter()
                .map(|s| s.centre.coords.norm() + s.radius)
                .fold(0.0, f64::max);
            Ok(vec![Sphere {
                centre: at * Point3::origin(),
                radius: reach,
            }])
        }
    }
}

/// The spheres covering `link`'s collision shapes, in the frame `at`.
fn shape_spheres(model: &RobotModel, link: usize, at: &Isometry3<f64>) -> Vec<Sphere> {
    let mut out = Vec::new();
    for Shape {
        origin, geometry, ..
    } in &model.links[link].collisions
    {
        let frame = at * origin_to_isometry(origin);
        let mut put = |x: f64, y: f64, z: f64, radius: f64| {
            out.push(Sphere {
                centre: frame * Point3::new(x, y, z),
                radius,
            })
        };
        let corners = |min: [f64; 3], max: [f64; 3], put: &mut dyn FnMut(f64, f64, f64, f64)| {
            for i in 0..8 {
                let pick = |k: usize| if i >> k & 1 == 0 { min[k] } else { max[k] };
                put(pick(0), pick(1), pick(2), 0.0);
            }
        };
        match geometry {
            Geometry::Sphere { radius } => put(0.0, 0.0, 0.0, *radius),
            Geometry::Capsule { radius, length } | Geometry::Cylinder { radius, length } => {
                put(0.0, 0.0, -length / 2.0, *radius);
                put(0.0, 0.0, length / 2.0, *radius);
            }
            Geometry::Box { size } => {
                let h = size.map(|v| v / 2.0);
                corners([-h[0], -h[1], -h[2]], h, &mut put);
            }
            Geometry::Mesh { scale, mesh, .. } => {
                if mesh.vertices.is_empty() {
                    continue;
                }
                let (lo, hi) = mesh.bounds();
                let (mut min, mut max) = ([0.0; 3], [0.0; 3]);
                for k in 0..3 {
                    let (a, b) = (lo[k] as f64 * scale[k], hi[k] as f64 * scale[k]);
                    (min[k], max[k]) = (a.min(b), a.max(b));
                }
                corners(min, max, &mut put);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Scene, SceneConfig};

    fn fr5_envelope() -> (Envelope, Scene) {
        let scene = Scene::new(SceneConfig::default()).unwrap();
        let envelope = Envelope::new(&scene.robot().model, "tcp").unwrap();
        (envelope, scene)
    }

    /// The lowest point of each part's spheres at `q`.
    fn lowest_by_part(envelope: &Envelope, q: &[f64]) -> Vec<(String, f64)> {
        let mut heights = Vec::new();
        envelope.first_outside(q, |c, r| {
            heights.push(c.z - r);
            true
        });
        let mut heights = heights.into_iter();
        let mut out: Vec<(String, f64)> = Vec::new();
        for part in envelope.links.iter().flatten() {
            let low = (heights.by_ref().take(part.spheres.len())).fold(f64::INFINITY, f64::min);
            match out.iter_mut().find(|(name, _)| *name == part.part) {
                Some((_, z)) => *z = z.min(low),
                None => out.push((part.part.clone(), low)),
            }
        }
        out
    }

    #[test]
    fn the_envelope_covers_links_and_fingers_but_not_the_base() {
        let (envelope, scene) = fr5_envelope();
        let parts: Vec<&str> = envelope
            .links
            .iter()
            .flatten()
            .map(|p| p.part.as_str())
            .collect();
        for name in [
            "upperarm_link",
            "forearm_link",
            "wrist3_link",
            "left_finger",
        ] {
            assert!(parts.contains(&name), "{name} missing from {parts:?}");
        }
        assert!(!parts.contains(&"base_link") && !parts.contains(&"shoulder_link"));
        // Fingers pointing down at the home pose: their lowest point is 20 mm past the TCP
        // (fingers 60 mm long from 60 mm below the gripper's base, TCP at 100 mm).
        let q: Vec<f64> = scene.arm_positions().iter().map(|&v| v as f64).collect();
        let tcp = envelope.chain().forward(&q).translation.vector;
        let heights = lowest_by_part(&envelope, &q);
        for finger in ["left_finger", "right_finger"] {
            let (_, z) = heights.iter().find(|(name, _)| name == finger).unwrap();
            assert!(
                (tcp.z - z - 0.02).abs() < 1e-4,
                "tcp {} {finger} {z}",
                tcp.z
            );
        }
    }

    #[test]
    fn a_capsule_is_covered_by_its_end_spheres() {
        let (envelope, scene) = fr5_envelope();
        let mut q: Vec<f64> = scene.arm_positions().iter().map(|&v| v as f64).collect();
        // Turning the shoulder moves the forearm's spheres; the check sees it.
        let forearm = |q: &[f64]| {
            let heights = lowest_by_part(&envelope, q);
            heights.iter().find(|(n, _)| n == "forearm_link").unwrap().1
        };
        let before = forearm(&q);
        q[1] += 0.3;
        let after = forearm(&q);
        assert!((after - before).abs() > 0.01, "{before} -> {after}");
        // A check refusing below a height names the part it refused, and where it is.
        let lowest = lowest_by_part(&envelope, &q).into_iter().fold(
            (String::new(), f64::INFINITY),
            |a, b| {
                if b.1 < a.1 { b } else { a }
            },
        );
        let (part, centre) = envelope
            .first_outside(&q, |c, r| c.z - r >= lowest.1 + 1e-9)
            .unwrap();
        assert_eq!(part, lowest.0);
        assert!(centre.z.is_finite());
    }
}
