//! Context features phi(s) of the linear policy mean W^T phi(s).
//!
//! Every built-in map puts the constant feature LAST, as BOLeRo does, because the initial policy
//! writes theta0 into the coefficients of the constant feature.

use std::fmt;
use std::sync::Arc;

use nalgebra::DVector;

use super::FeatureMapValidateError;

/// The signature of a user-supplied feature function.
pub type FeatureFn = dyn Fn(&[f64]) -> Vec<f64> + Send + Sync;

/// A user-supplied feature map.
#[derive(Clone)]
pub struct CustomFeatures {
    /// Maps a context to exactly `dim` features.
    pub function: Arc<FeatureFn>,
    /// The number of features `function` returns.
    pub dim: usize,
    /// The index of a feature that is always 1, if there is one. Without it the initial mean
    /// cannot be theta0 for every context, so [`CReps::new`](super::CReps::new) then requires
    /// theta0 = 0.
    pub constant: Option<usize>,
}

impl fmt::Debug for CustomFeatures {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CustomFeatures")
            .field("dim", &self.dim)
            .field("constant", &self.constant)
            .finish_non_exhaustive()
    }
}

/// Which features of the context the policy mean is linear in.
#[derive(Clone, Debug, Default)]
pub enum FeatureMap {
    /// `[s_0, ..., s_{d-1}, 1]`. The default: the fewest features (d + 1) with a constant one,
    /// so the fewest rollouts per update are needed to fit W. Choose [`Quadratic`](Self::Quadratic)
    /// when the best parameters bend with the context, as the paper does in Sec. 5.1.
    #[default]
    Affine,
    /// All monomials of degree <= 2: the `d(d+1)/2` products `s_i s_j` (i <= j, lexicographic:
    /// `s_0^2, s_0 s_1, ..., s_{d-1}^2`), then `s_0, ..., s_{d-1}`, then 1 (P Sec. 2.1: "linear
    /// and quadratic terms of s").
    Quadratic,
    /// For a 2-D context only: the polar coordinates `r = ||s||`, `a = atan2(s_1, s_0)` in
    /// (-pi, pi], and their quadratic monomials `[r^2, r a, a^2, r, a, 1]` (P Sec. 5.2.2, which
    /// leaves the angle convention open). The angle jumps on the negative s_0 axis, so the
    /// contexts should stay away from it (the paper's targets lie in the third quadrant).
    PolarQuadratic,
    /// A user-supplied map.
    Custom(CustomFeatures),
}

impl FeatureMap {
    /// The number of features for a context of `context_dim` dimensions.
    pub fn dim(&self, context_dim: usize) -> usize {
        match self {
            FeatureMap::Affine => context_dim + 1,
            FeatureMap::Quadratic => context_dim * (context_dim + 1) / 2 + context_dim + 1,
            FeatureMap::PolarQuadratic => 6,
            FeatureMap::Custom(custom) => custom.dim,
        }
    }

    /// The index of the constant feature, if the map has one.
    pub fn constant_index(&self, context_dim: usize) -> Option<usize> {
        match self {
            FeatureMap::Custom(custom) => custom.constant,
            _ => Some(self.dim(context_dim) - 1),
        }
    }

    /// The features of `context`.
    ///
    /// # Panics
    /// If a custom function returns a length other than its declared `dim` (a broken contract
    /// that no caller could recover from).
    pub fn apply(&self, context: &[f64]) -> DVector<f64> {
        let features = match self {
            FeatureMap::Affine => context.iter().copied().chain([1.0]).collect(),
            FeatureMap::Quadratic => quadratic_monomials(context),
            FeatureMap::PolarQuadratic => {
                let radius = context[0].hypot(context[1]);
                let angle = context[1].atan2(context[0]);
                quadratic_monomials(&[radius, angle])
            }
            FeatureMap::Custom(custom) => {
                let features = (custom.function)(context);
                assert_eq!(
                    features.len(),
                    custom.dim,
                    "custom feature function returned {} features, declared dim is {}",
                    features.len(),
                    custom.dim
                );
                features
            }
        };
        DVector::from_vec(features)
    }

    /// The features of `context`, which a learner for `context_dim`-dimensional contexts was
    /// handed.
    ///
    /// # Panics
    /// If `context.len() != context_dim`.
    pub(crate) fn apply_sized(&self, context: &[f64], context_dim: usize) -> DVector<f64> {
        assert_eq!(
            context.len(),
            context_dim,
            "context has {} entries, context_dim is {}",
            context.len(),
            context_dim
        );
        self.apply(context)
    }

    /// Checks that this map works for `context_dim`-dimensional contexts and for the initial
    /// mean `theta0`.
    pub(crate) fn validate(&self, context_dim: usize, theta0: &[f64]) -> Result<(), FeatureMapValidateError> {
        let context_dim_error = |feature_map, expected| FeatureMapValidateError::ContextDim {
            feature_map,
            expected,
            got: context_dim,
        };
        match self {
            FeatureMap::Affine if context_dim == 0 => Err(context_dim_error("Affine", ">= 1")),
            FeatureMap::Quadratic if context_dim == 0 => Err(context_dim_error("Quadratic", ">= 1")),
            FeatureMap::PolarQuadratic if context_dim != 2 => Err(context_dim_error("PolarQuadratic", "exactly 2")),
            FeatureMap::Custom(custom) => validate_custom(custom, context_dim, theta0),
            _ => Ok(()),
        }
    }
}

fn validate_custom(custom: &CustomFeatures, context_dim: usize, theta0: &[f64]) -> Result<(), FeatureMapValidateError> {
    if context_dim == 0 {
        return Err(FeatureMapValidateError::ContextDim {
            feature_map: "Custom",
            expected: ">= 1",
            got: context_dim,
        });
    }
    if custom.dim == 0 {
        return Err(FeatureMapValidateError::NoFeatures);
    }
    // One probe at the zero context catches a wrong declared dim or a constant that is not 1;
    // other non-finite values there are allowed (the function may be singular at 0).
    let probe = (custom.function)(&vec![0.0; context_dim]);
    if probe.len() != custom.dim {
        return Err(FeatureMapValidateError::Length {
            got: probe.len(),
            dim: custom.dim,
        });
    }
    match custom.constant {
        Some(index) if index >= custom.dim => Err(FeatureMapValidateError::ConstantIndex { index, dim: custom.dim }),
        Some(index) if probe[index] != 1.0 => Err(FeatureMapValidateError::ConstantValue {
            index,
            value: probe[index],
        }),
        None if theta0.iter().any(|&t| t != 0.0) => Err(FeatureMapValidateError::NoConstantFeature),
        _ => Ok(()),
    }
}

/// `[x_i x_j for i <= j] ++ x ++ [1]`.
fn quadratic_monomials(x: &[f64]) -> Vec<f64> {
    let d = x.len();
    let mut features = Vec::with_capacity(d * (d + 1) / 2 + d + 1);
    for i in 0..d {
        features.extend(x[i..].iter().map(|&xj| x[i] * xj));
    }
    features.extend_from_slice(x);
    features.push(1.0);
    features
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_features(map: &FeatureMap, context: &[f64], expected: &[f64]) {
        let features = map.apply(context);
        assert_eq!(features.len(), map.dim(context.len()));
        for (got, want) in features.iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{features} vs {expected:?}");
        }
        assert_eq!(features.len(), expected.len());
        assert_eq!(map.constant_index(context.len()), Some(expected.len() - 1));
    }

    #[test]
    fn builtin_maps_have_the_documented_values_and_dims() {
        assert_features(&FeatureMap::Affine, &[2.0, -3.0], &[2.0, -3.0, 1.0]);
        assert_features(&FeatureMap::Quadratic, &[2.0], &[4.0, 2.0, 1.0]);
        assert_features(&FeatureMap::Quadratic, &[2.0, -3.0], &[4.0, -6.0, 9.0, 2.0, -3.0, 1.0]);
        assert_features(
            &FeatureMap::Quadratic,
            &[1.0, 2.0, 3.0],
            &[1.0, 2.0, 3.0, 4.0, 6.0, 9.0, 1.0, 2.0, 3.0, 1.0],
        );
        let a = 4.0f64.atan2(-3.0);
        assert_features(
            &FeatureMap::PolarQuadratic,
            &[-3.0, 4.0],
            &[25.0, 5.0 * a, a * a, 5.0, a, 1.0],
        );
        assert_eq!(FeatureMap::Quadratic.dim(4), 15);
    }

    #[test]
    fn custom_map_is_validated() {
        let custom = |dim, constant| {
            FeatureMap::Custom(CustomFeatures {
                function: Arc::new(|s: &[f64]| vec![s[0].sin(), 1.0]),
                dim,
                constant,
            })
        };
        assert!(custom(2, Some(1)).validate(1, &[3.0]).is_ok());
        assert_eq!(custom(2, Some(1)).apply(&[0.5]).as_slice(), &[0.5f64.sin(), 1.0]);
        assert!(custom(2, None).validate(1, &[0.0]).is_ok());
        let message = |map: FeatureMap| map.validate(1, &[3.0]).unwrap_err().to_string();
        assert!(message(custom(2, None)).contains("theta0"));
        assert!(message(custom(3, Some(1))).contains("dim"));
        assert!(message(custom(2, Some(2))).contains("constant"));
        assert!(message(custom(2, Some(0))).contains("constant"));
        assert!(message(custom(0, Some(0))).contains("dim must be >= 1"));
    }

    #[test]
    fn context_dim_requirements_name_the_map() {
        let error = FeatureMap::PolarQuadratic.validate(3, &[0.0]).unwrap_err();
        assert_eq!(
            error.to_string(),
            "context_dim must be exactly 2 for the PolarQuadratic feature map, got 3"
        );
        assert!(FeatureMap::Affine.validate(0, &[0.0]).is_err());
        assert!(FeatureMap::Quadratic.validate(0, &[0.0]).is_err());
        assert!(FeatureMap::PolarQuadratic.validate(2, &[0.0]).is_ok());
    }
}
