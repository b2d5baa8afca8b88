//! The acps learner.
pub mod selection;
