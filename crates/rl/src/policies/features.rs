//! Feature extractors (SB3's `BaseFeaturesExtractor`): what turns an observation into the
//! vector the policy and value heads read. Flat observations need nothing ([`FlattenExtractor`],
//! SB3's default); an image encoder joins as another [`FeaturesConfig`] variant, and PPO and
//! SAC build whichever the configuration names.

use candle_core::Tensor;
use candle_nn::{VarBuilder, VarMap};
use rand::RngCore;
use serde::{Deserialize, Serialize};

/// Maps a batch of observations (`batch × obs_dim`) to features (`batch × features_dim`).
pub trait FeaturesExtractor: Send + Sync {
    /// Values per feature vector.
    fn features_dim(&self) -> usize;

    /// The features of `obs` (`batch × obs_dim`): `batch × features_dim`.
    fn forward(&self, obs: &Tensor) -> candle_core::Result<Tensor>;

    /// Draws initial weights from `rng` (so a seed fixes the network); `varmap` is the map the
    /// extractor was built in. Parameter-free extractors have nothing to draw.
    fn init_weights(&self, _varmap: &VarMap, _rng: &mut dyn RngCore) -> candle_core::Result<()> {
        Ok(())
    }
}

/// Which feature extractor a network starts with (`[ppo.features]` / `[sac.features]`,
/// `kind = "flatten"` by default).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FeaturesConfig {
    /// The observation as it is (flat vectors). A struct variant, so that stray keys beside
    /// `kind` are refused.
    Flatten {},
}

impl Default for FeaturesConfig {
    fn default() -> Self {
        FeaturesConfig::Flatten {}
    }
}

impl FeaturesConfig {
    /// The extractor for `obs_dim`-value observations, its parameters (if any) created under
    /// `vb` (with zero values until [`FeaturesExtractor::init_weights`]).
    pub fn build(
        &self,
        _vb: &VarBuilder,
        obs_dim: usize,
    ) -> candle_core::Result<Box<dyn FeaturesExtractor>> {
        match self {
            FeaturesConfig::Flatten {} => Ok(Box::new(FlattenExtractor::new(obs_dim))),
        }
    }
}

/// The identity on flat observations; it has no parameters.
#[derive(Clone, Debug)]
pub struct FlattenExtractor {
    dim: usize,
}

impl FlattenExtractor {
    /// The extractor for `obs_dim`-value observations.
    pub fn new(obs_dim: usize) -> Self {
        Self { dim: obs_dim }
    }
}

impl FeaturesExtractor for FlattenExtractor {
    fn features_dim(&self) -> usize {
        self.dim
    }

    /// Rows of more than one dimension are flattened, as SB3's `nn.Flatten` does.
    fn forward(&self, obs: &Tensor) -> candle_core::Result<Tensor> {
        if obs.rank() == 2 {
            Ok(obs.clone())
        } else {
            obs.flatten_from(1)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{DType, Device};

    #[test]
    fn flatten_is_the_identity_without_parameters() {
        let varmap = VarMap::new();
        let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
        let extractor = FeaturesConfig::default()
            .build(&vb.pp("features"), 3)
            .unwrap();
        assert_eq!(extractor.features_dim(), 3);
        let obs = Tensor::new(&[[1.0f32, -2.0, 3.5], [0.0, 4.0, -1.0]], &Device::Cpu).unwrap();
        let out = extractor.forward(&obs).unwrap();
        assert_eq!(out.to_vec2::<f32>().unwrap(), obs.to_vec2::<f32>().unwrap());
        let images = Tensor::zeros((2, 1, 3), DType::F32, &Device::Cpu).unwrap();
        assert_eq!(extractor.forward(&images).unwrap().dims(), [2, 3]);
        assert!(varmap.all_vars().is_empty());
    }

    #[test]
    fn the_config_is_tagged_by_kind_and_defaults_to_flatten() {
        #[derive(Deserialize)]
        struct Section {
            #[serde(default)]
            features: FeaturesConfig,
        }
        let parse = |text: &str| toml::from_str::<Section>(text).map(|s| s.features);
        assert_eq!(parse("").unwrap(), FeaturesConfig::Flatten {});
        assert_eq!(
            parse("[features]\nkind = \"flatten\"\n").unwrap(),
            FeaturesConfig::Flatten {}
        );
        let err = parse("[features]\nkind = \"nature_cnn\"\n").err().unwrap();
        assert!(err.to_string().contains("nature_cnn"), "{err}");
        let err = parse("[features]\nkind = \"flatten\"\nwidth = 3\n")
            .err()
            .unwrap();
        assert!(err.to_string().contains("width"), "{err}");
    }
}
