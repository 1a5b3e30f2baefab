//! `--config`, `--physics-hz`, `--substeps`, `--urdf`, `--package-path`: the scene settings the
//! commands that build a scene share.

use anyhow::{Context, Result};
use fairgrasp_sim::scene::SceneConfig;
use std::path::{Path, PathBuf};

/// Scene settings shared by the commands that build a scene.
#[derive(clap::Args, Clone, Debug)]
pub struct SceneArgs {
    /// TOML file with scene settings (sections: physics, table, object, placement, gripper, arm).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Physics rate in Hz (overrides the config; 240 by default).
    #[arg(long)]
    pub physics_hz: Option<f32>,
    /// Physics steps per control step (overrides the config).
    #[arg(long)]
    pub substeps: Option<u32>,
    /// Arm URDF to use instead of the bundled FR5.
    #[arg(long)]
    pub urdf: Option<PathBuf>,
    /// Directories searched for `package://` meshes (also: ROS_PACKAGE_PATH).
    #[arg(long = "package-path")]
    pub package_paths: Vec<PathBuf>,
}

impl SceneArgs {
    /// The scene configuration: defaults, then the TOML file, then flags.
    pub fn scene_config(&self) -> Result<SceneConfig> {
        let mut config = match &self.config {
            Some(path) => load_scene_config(path)?,
            None => SceneConfig::default(),
        };
        if let Some(hz) = self.physics_hz {
            anyhow::ensure!(
                hz.is_finite() && hz > 0.0,
                "--physics-hz must be positive, got {hz}"
            );
            // Keep the control period when only the physics rate changes.
            let period = config.physics.dt * config.physics.substeps as f32;
            config.physics.dt = 1.0 / hz;
            if self.substeps.is_none() {
                config.physics.substeps = (period * hz).round().max(1.0) as u32;
            }
        }
        if let Some(k) = self.substeps {
            config.physics.substeps = k;
        }
        if let Some(urdf) = &self.urdf {
            config.arm.urdf = Some(urdf.clone());
        }
        config
            .arm
            .package_paths
            .extend(self.package_paths.iter().cloned());
        config.validate()?;
        Ok(config)
    }
}

/// Reads a scene TOML file; unknown keys and bad values are errors naming the key.
pub fn load_scene_config(path: &Path) -> Result<SceneConfig> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read config {}", path.display()))?;
    let config: SceneConfig =
        toml::from_str(&text).with_context(|| format!("invalid config {}", path.display()))?;
    config
        .validate()
        .with_context(|| format!("invalid config {}", path.display()))?;
    Ok(config)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_documented_scene_config_is_the_default() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/scene.toml");
        let config = load_scene_config(&path).unwrap();
        let default = SceneConfig::default();
        // The file writes 1/240 and π/2 with fewer digits than f32 holds.
        assert!((config.physics.dt - default.physics.dt).abs() < 1e-8);
        let mut config = config;
        config.physics.dt = default.physics.dt;
        for (a, b) in config.arm.home.iter_mut().zip(&default.arm.home) {
            assert!((*a - b).abs() < 1e-4);
            *a = *b;
        }
        config.placement.yaw_range = default.placement.yaw_range;
        assert_eq!(config, default);
    }
}
