// Empty: a build script makes cargo resolve this package's build-dependencies, which unify the
// features of crates that build scripts and proc-macros use.
fn main() {}
