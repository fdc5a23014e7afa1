//! What ReSTIR reports about itself: the names in its checkpointed state and what its merge
//! counted.
use super::Diagnostics;

/// Names in the ReSTIR estimator's [`EstimatorState`](super::EstimatorState): the kept reservoirs (two per texel,
/// sign 0 then sign 1, [`reservoir::WORDS`](super::reservoir::WORDS) words each), the target adjoints of both parities
/// (RGBA f32 per pixel, the cameras one after another, the even iterations' first: the
/// resampling targets' smoothed adjoint), and the merges whose samples the kept reservoirs can
/// hold (0 before the first iteration or without temporal reuse; it sets the kept samples'
/// confidence).
pub mod state_names {
    /// Array: the kept reservoirs.
    pub const RESERVOIRS: &str = "reservoirs";
    /// Array: the target adjoints.
    pub const TARGETS: &str = "targets";
    /// Counter: the merges so far.
    pub const HISTORY: &str = "history";
    /// Array: the moving mean and second moment of the fresh estimates, per gradient entry
    /// (the variance the merge reports).
    pub const FRESH_MOMENTS: &str = "fresh moments";
    /// Counter: the merges that updated them.
    pub const MOMENT_UPDATES: &str = "moment updates";
    /// Counter: words per reservoir ([`reservoir::WORDS`](super::super::reservoir::WORDS); a state saved with another
    /// reservoir layout is refused).
    pub const WORDS: &str = "reservoir words";
}

/// What the merge pass counted since the optimizer was created.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MergeDiagnostics {
    /// BRDF evaluations of stored paths (the merge's whole work; it traces no ray).
    pub evaluations: u64,
    /// Kept paths checked with [`RestirOptions::verify_paths`](super::RestirOptions::verify_paths).
    pub verified: u64,
    /// Largest relative difference between a stored path's target under the previous state
    /// (stored with it, in bfloat16) and its evaluation there.
    pub max_relative_error: f32,
    /// Candidates for texels outside the compaction map (texels that the observed-texel
    /// pass's strata missed), dropped by the candidate pass.
    pub unmapped: u64,
    /// Offers entered in the claim log (the leaders of their reservoirs' races when they
    /// entered them).
    pub logged: u64,
    /// Offers the full claim log could not take: each iteration where one did traced its
    /// samples a second time.
    pub overflowed: u64,
}

impl MergeDiagnostics {
    pub(super) const EVALUATIONS: &'static str = "merge evaluations";
    const VERIFIED: &'static str = "merge verified";
    const MAX_RELATIVE_ERROR: &'static str = "merge max relative error";
    pub(super) const UNMAPPED: &'static str = "candidates unmapped";
    pub(super) const LOGGED: &'static str = "claims logged";
    pub(super) const OVERFLOWED: &'static str = "claims overflowed";

    pub(super) fn named(&self) -> Diagnostics {
        vec![
            (Self::EVALUATIONS, self.evaluations as f64),
            (Self::VERIFIED, self.verified as f64),
            (Self::MAX_RELATIVE_ERROR, f64::from(self.max_relative_error)),
            (Self::UNMAPPED, self.unmapped as f64),
            (Self::LOGGED, self.logged as f64),
            (Self::OVERFLOWED, self.overflowed as f64),
        ]
    }

    /// What the ReSTIR merge counted, read from an estimator's named diagnostics (the
    /// optimizer's `estimator_diagnostics()`; None when it runs another estimator).
    pub fn from_named(d: &Diagnostics) -> Option<MergeDiagnostics> {
        let get = |name: &str| d.iter().find(|(n, _)| *n == name).map(|v| v.1);
        match (
                get(Self::EVALUATIONS),
                get(Self::VERIFIED),
                get(Self::MAX_RELATIVE_ERROR),
                get(Self::UNMAPPED),
            ) {
            (Some(e), Some(v), Some(m), Some(u)) => Some(MergeDiagnostics {
                evaluations: e as u64,
                verified: v as u64,
                max_relative_error: m as f32,
                unmapped: u as u64,
                logged: get(Self::LOGGED).unwrap_or(0.0) as u64,
                overflowed: get(Self::OVERFLOWED).unwrap_or(0.0) as u64,
            }),
            _ => None,
        }
    }
}
