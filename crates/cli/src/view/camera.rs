//! The page's orbit camera: azimuth, elevation and distance around a target point, read from a
//! frame request's query string and turned into the renderer's look-at camera.

use fairgrasp_render::CameraConfig;

/// A rendered frame: width, height and RGB bytes (row-major).
pub type RgbFrame = (u32, u32, Vec<u8>);

/// An orbit camera as the page sends it (angles in degrees, lengths in metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orbit {
    pub azimuth_deg: f32,
    pub elevation_deg: f32,
    pub distance: f32,
    pub target: [f32; 3],
}

impl Default for Orbit {
    /// The renderer's default front-three-quarter view, as an orbit.
    fn default() -> Self {
        Self {
            azimuth_deg: -40.8,
            elevation_deg: 22.4,
            distance: 1.57,
            target: [0.35, 0.0, 0.85],
        }
    }
}

impl Orbit {
    /// Reads `az`, `el`, `dist`, `tx`, `ty`, `tz` from a query string (each optional; unknown
    /// keys such as a cache-busting `t` are ignored). Values must be finite and in range.
    pub fn from_query(query: &str) -> Result<Self, String> {
        let mut orbit = Orbit::default();
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
            let slot = match key {
                "az" => &mut orbit.azimuth_deg,
                "el" => &mut orbit.elevation_deg,
                "dist" => &mut orbit.distance,
                "tx" => &mut orbit.target[0],
                "ty" => &mut orbit.target[1],
                "tz" => &mut orbit.target[2],
                _ => continue,
            };
            *slot = value
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{key}` must be a finite number, got `{value}`"))?;
        }
        if !(-89.9..=89.9).contains(&orbit.elevation_deg) {
            return Err(format!(
                "`el` must be within ±89.9 degrees, got {}",
                orbit.elevation_deg
            ));
        }
        if !(0.1..=20.0).contains(&orbit.distance) {
            return Err(format!(
                "`dist` must be within 0.1 and 20 m, got {}",
                orbit.distance
            ));
        }
        if orbit.target.iter().any(|t| t.abs() > 10.0) {
            return Err(format!(
                "the target must lie within 10 m of the origin, got {:?}",
                orbit.target
            ));
        }
        Ok(orbit)
    }

    /// The renderer's camera for this orbit at the given image size (z up).
    pub fn camera(&self, width: u32, height: u32) -> CameraConfig {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        let t = self.target;
        let d = self.distance;
        CameraConfig {
            eye: [
                t[0] + d * el.cos() * az.cos(),
                t[1] + d * el.cos() * az.sin(),
                t[2] + d * el.sin(),
            ],
            target: t,
            ..CameraConfig::front_three_quarter(width, height)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_orbit_is_near_the_default_camera() {
        let orbit = Orbit::default().camera(64, 48);
        let reference = CameraConfig::front_three_quarter(64, 48);
        for (a, b) in orbit.eye.iter().zip(reference.eye) {
            assert!(
                (a - b).abs() < 0.02,
                "{:?} vs {:?}",
                orbit.eye,
                reference.eye
            );
        }
    }

    #[test]
    fn bad_queries_are_errors_that_name_the_key() {
        assert!(Orbit::from_query("az=NaN").unwrap_err().contains("az"));
        assert!(Orbit::from_query("dist=abc").unwrap_err().contains("dist"));
        assert!(Orbit::from_query("el=95").unwrap_err().contains("el"));
        assert!(Orbit::from_query("dist=0").is_err());
        let orbit = Orbit::from_query("az=10&el=-5&dist=2&t=7").unwrap();
        assert_eq!(
            (orbit.azimuth_deg, orbit.elevation_deg, orbit.distance),
            (10.0, -5.0, 2.0)
        );
    }
}
