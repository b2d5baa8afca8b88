//! No code. Its dependencies turn on, in every build of `acps`, the features the workspace's
//! test build turns on in them, so that one compile of each serves both (see Cargo.toml).
