//! Tests only (`tests/export.rs`): the ONNX graphs `fairgrasp export` writes, run by a real
//! runtime (tract), give the actions of our own inference.
//!
//! A package of its own because a dev-dependency links into every test binary of its package:
//! with tract beside `fairgrasp-deploy`'s sixteen test binaries, each linked it, and tract
//! (built at opt-level 0 in the dev profile to keep the test build short) lent them its
//! unoptimised copies of shared generic functions, which made the safety filter's million-output
//! test 4.1× slower (26 s → 109 s, Intel Xeon 2-vCPU).
