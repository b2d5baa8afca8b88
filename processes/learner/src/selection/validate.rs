//! Input checks shared by the selectors' constructors.

use super::SelectorCreateError;
use acps_shared::ContextSpace;

/// Check that `contexts` is non-empty and that every context has `expected_dim` finite
/// coordinates (by default the dimension of context 0, which must be at least 1).
pub(crate) fn check_contexts(contexts: &[Vec<f64>], expected_dim: Option<usize>) -> Result<(), SelectorCreateError> {
    let first = contexts.first().ok_or(SelectorCreateError::NoContexts)?;
    let expected_dim = expected_dim.unwrap_or(first.len()).max(1);
    match contexts
        .iter()
        .position(|c| c.len() != expected_dim || !c.iter().all(|x| x.is_finite()))
    {
        Some(index) => Err(SelectorCreateError::InvalidContext {
            index,
            expected_dim,
            context: contexts[index].clone(),
        }),
        None => Ok(()),
    }
}

/// Check the space of a selector that draws from it and, when it snaps its draws to training
/// contexts, that they are valid contexts of the space's dimension.
pub(crate) fn check_space_and_snap(
    space: &ContextSpace,
    snap_to: Option<&[Vec<f64>]>,
) -> Result<(), SelectorCreateError> {
    check_space(space)?;
    match snap_to {
        Some(contexts) => check_contexts(contexts, Some(space.dim())),
        None => Ok(()),
    }
}

/// Check a context space again: its fields are public, so it may not have come from a validating
/// constructor, and sampling from an inverted box would panic.
pub(crate) fn check_space(space: &ContextSpace) -> Result<(), SelectorCreateError> {
    match space {
        ContextSpace::Box { low, high } => ContextSpace::new_box(low.clone(), high.clone())?,
        ContextSpace::Ball { dim, radius } => ContextSpace::new_ball(*dim, *radius)?,
    };
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contexts_must_be_non_empty_finite_and_of_one_dimension() {
        assert_eq!(check_contexts(&[], None), Err(SelectorCreateError::NoContexts));
        assert!(check_contexts(&[vec![0.0, 1.0], vec![2.0, 3.0]], None).is_ok());
        let err = check_contexts(&[vec![0.0, 1.0], vec![2.0]], None).unwrap_err();
        assert_eq!(
            err.to_string(),
            "training context 1 must have 2 finite coordinates, got [2.0]"
        );
        assert!(check_contexts(&[vec![0.0], vec![f64::NAN]], None).is_err());
        assert!(check_contexts(&[vec![]], None).is_err());
        assert!(check_contexts(&[vec![0.0]], Some(2)).is_err());
    }

    #[test]
    fn hand_built_invalid_spaces_are_refused() {
        let inverted = ContextSpace::Box {
            low: vec![1.0],
            high: vec![0.0],
        };
        assert!(matches!(check_space(&inverted), Err(SelectorCreateError::Space(_))));
        let flat = ContextSpace::Ball { dim: 2, radius: 0.0 };
        assert!(check_space(&flat).is_err());
        assert!(check_space(&ContextSpace::new_ball(2, 1.0).unwrap()).is_ok());
    }
}
