//! Empty: Cargo takes a package's build-dependencies (here, only for their features) only when
//! it has a build script.
fn main() {}
