//! `fairgrasp inspect ROBOT.urdf`: what PyBullet's getJointInfo shows, for any URDF.

use anyhow::{Context, Result};
use fairgrasp_sim::kinematics::SerialChain;
use fairgrasp_sim::model::{Geometry, LoadOptions, PackagePaths, RobotModel};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct InspectArgs {
    /// URDF file (xacro must be expanded first).
    pub urdf: PathBuf,
    /// Directories searched for `package://` meshes, before ROS_PACKAGE_PATH.
    #[arg(long = "package-path")]
    pub package_paths: Vec<PathBuf>,
    /// End link of the chain to report (default: the leaf reached along movable joints).
    #[arg(long)]
    pub end_link: Option<String>,
}

fn fmt_limit(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

pub fn run(args: &InspectArgs) -> Result<()> {
    let options = LoadOptions {
        packages: PackagePaths::from_env().with_first(args.package_paths.iter().cloned()),
    };
    let model = RobotModel::load(&args.urdf, &options)?;
    println!(
        "robot '{}' from {}: {} links, {} joints ({} movable)",
        model.name,
        args.urdf.display(),
        model.links.len(),
        model.joints.len(),
        model.joints.iter().filter(|j| j.kind.is_movable()).count()
    );
    println!();
    println!(
        "{:>3}  {:<20} {:<10} {:<18} {:<18} {:<16} {:>9} {:>9} {:>8} {:>8}",
        "idx", "joint", "type", "parent", "child", "axis", "lower", "upper", "effort", "velocity"
    );
    for (i, j) in model.joints.iter().enumerate() {
        let (lower, upper, effort, velocity) = match j.limits {
            Some(l) => (
                fmt_limit(l.lower),
                fmt_limit(l.upper),
                fmt_limit(l.effort),
                fmt_limit(l.velocity),
            ),
            None => ("-".into(), "-".into(), "-".into(), "-".into()),
        };
        let axis = if j.kind.is_movable() {
            format!("({:.2}, {:.2}, {:.2})", j.axis[0], j.axis[1], j.axis[2])
        } else {
            "-".into()
        };
        let kind = match j.mimic {
            Some(_) => format!("{}*", j.kind.as_str()),
            None => j.kind.as_str().to_string(),
        };
        println!(
            "{i:>3}  {:<20} {:<10} {:<18} {:<18} {:<16} {:>9} {:>9} {:>8} {:>8}",
            j.name,
            kind,
            model.links[j.parent].name,
            model.links[j.child].name,
            axis,
            lower,
            upper,
            effort,
            velocity
        );
    }
    if model.joints.iter().any(|j| j.mimic.is_some()) {
        println!("     (* mimics another joint)");
    }

    println!();
    println!(
        "{:<20} {:>9} {:>10} {:>8}  meshes",
        "link", "mass kg", "collision", "visual"
    );
    for link in &model.links {
        let meshes: Vec<String> = link
            .collisions
            .iter()
            .chain(&link.visuals)
            .filter_map(|s| match &s.geometry {
                Geometry::Mesh { uri, mesh, .. } => {
                    Some(format!("{uri} ({} triangles)", mesh.triangles.len()))
                }
                _ => None,
            })
            .collect();
        println!(
            "{:<20} {:>9} {:>10} {:>8}  {}",
            link.name,
            link.inertial
                .map(|i| format!("{:.4}", i.mass))
                .unwrap_or_else(|| "-".into()),
            link.collisions.len(),
            link.visuals.len(),
            meshes.join(", ")
        );
    }

    let end = match &args.end_link {
        Some(name) => model
            .link_index(name)
            .with_context(|| format!("no link named '{name}'"))?,
        None => model.end_link(),
    };
    let chain_links: Vec<&str> = std::iter::once(model.links[model.root].name.as_str())
        .chain(
            model
                .chain_to(end)
                .into_iter()
                .map(|j| model.links[model.joints[j].child].name.as_str()),
        )
        .collect();
    println!();
    println!("chain: {}", chain_links.join(" -> "));
    let chain = SerialChain::new(&model, &model.links[end].name)?;
    let zero = vec![0.0; chain.dof()];
    let pose = chain.forward(&zero);
    let (roll, pitch, yaw) = pose.rotation.euler_angles();
    let t = pose.translation.vector;
    println!(
        "{} pose at q = 0 ({} joints): xyz = ({:.4}, {:.4}, {:.4}) m, rpy = ({:.4}, {:.4}, {:.4}) rad",
        model.links[end].name,
        chain.dof(),
        t.x,
        t.y,
        t.z,
        roll,
        pitch,
        yaw
    );
    Ok(())
}
