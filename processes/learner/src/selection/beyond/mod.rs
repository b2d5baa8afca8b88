//! Teachers beyond the paper: later curricula, and the retirement of solved contexts the
//! paper's outlook asks for (Sec. 6).
//!
//! - `absolute_progress`: [`AbsoluteProgress`], training contexts drawn in proportion to the
//!   absolute difference of a fast and a slow moving average of their returns (Kanitscheider et
//!   al. 2021); `progress` keeps those averages ([`ReturnAverages`]).
//! - `retire`: [`RetireConfig`], [`BanditSelector`](crate::selection::BanditSelector) and
//!   [`AbsoluteProgress`] may retire solved contexts and bring them back when their return falls.
//! - `alp_gmm`: [`AlpGmm`], contexts drawn from the continuous space where a Gaussian mixture
//!   over (context, absolute learning progress) places the progress (Portelas et al. 2019);
//!   `gmm` fits the mixture, `neighbours` finds the nearest earlier context.
//! - `self_paced`: [`SelfPaced`], SPRL's context distribution that C-REPS moves with the policy
//!   (Klink et al. 2019).

mod absolute_progress;
mod alp_gmm;
mod gmm;
mod neighbours;
mod progress;
mod retire;
mod self_paced;

pub use absolute_progress::{AbsoluteProgress, AbsoluteProgressConfig, AbsoluteProgressState};
pub use alp_gmm::{AlpGmm, AlpGmmConfig, AlpGmmState};
pub use gmm::Component;
pub use progress::{EmaRates, ReturnAverages};
pub use retire::{RetireConfig, Retirement, RetirementState};
pub use self_paced::{MAX_DRAWS, SelfPaced, SelfPacedConfig, SelfPacedState};
