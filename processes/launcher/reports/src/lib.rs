//! Reports of acps run directories: the pictures written beside `summary.json` ([`plot`]), the
//! paired statistics of `acps compare` ([`compare`]), and the rows of `acps bench` ([`mod@bench`]).
#![warn(missing_docs)]

pub mod bench;
pub mod compare;
pub mod plot;
