//! Integration tests of acps, one binary with a module per theme.

mod learner_core;
mod paper_claims;
mod resume;
