//! Empty on purpose: this package only depends, with the features listed in its Cargo.toml.
//!
//! Every package of the workspace depends on it, so building one package on its own
//! (`maturin develop` for the Python module, `cargo build -p fairgrasp-cli`) asks for the same
//! features of each third-party crate as `cargo test --workspace`, and cargo reuses what the test
//! build compiled instead of building the dependency tree a second time. `cargo hakari generate`
//! writes the list; `scripts/check_features.py` (in `.ci/run`) checks it still holds.
