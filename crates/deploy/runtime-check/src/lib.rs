//! Tests only (`tests/export.rs`): the ONNX graphs `fairgrasp export` writes, run by a real
//! runtime (tract), give the actions of our own inference.
//!
//! A package of its own because a dev-dependency links into every test binary of its package,
//! and tract is built at opt-level 0 in the dev profile (530 s of CPU at opt-level 3, a quarter
//! of a fresh test build). A crate at opt-level 0 lends its unoptimised instances of shared
//! generic functions to the opt-level-1 crates it is linked into: tokenizers at opt-level 0
//! (under candle-core, so linked into everything) made the safety filter's million-output test
//! 4.4× slower (24 s → 107 s, Intel Xeon 2-vCPU). Here tract reaches these tests alone.
