//! ReSTIR's options: the task file's `[optimizer.restir]`, `--estimator-option
//! restir.KEY=VALUE` on the command line, and what `bench --tune` searches.

/// Confidence of the fresh candidates in the merge (the kept sample's is min(M, M-cap)).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Confidence {
    /// Gradient samples per pixel (the reference code's M_c = spp; the pixel count cancels).
    #[default]
    Samples,
    /// Candidates per pixel and texel: 2 techniques x gradient spp x cameras.
    Candidates,
}

impl Confidence {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Confidence::Samples => "samples",
            Confidence::Candidates => "candidates",
        }
    }
}

/// How the ReSTIR estimator reuses samples: the options table `[optimizer.restir]` of a task
/// file, `--estimator-option restir.KEY=VALUE` on the command line.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RestirOptions {
    /// Cap on the confidence of the kept samples (the knob between reuse and staleness): they
    /// weigh min(M_c x merges so far, m_cap) against the fresh candidates' M_c.
    pub m_cap: f32,
    /// Confidence of the fresh candidates.
    pub confidence: Confidence,
    /// Temporal reuse across iterations; without it, resampling within the iteration only.
    pub temporal: bool,
    /// Two reservoirs per texel (positive and negative part of the target); without it, one
    /// over |target|.
    pub positivization: bool,
    /// Self-check of the stored paths: the merge also evaluates every kept path under the
    /// state it was drawn at and records the largest relative difference from its stored
    /// factor ([`super::MergeDiagnostics`]). Costs one more BRDF evaluation per kept sample.
    pub verify_paths: bool,
    /// Weight of the last iteration's target adjoint in this one's, in [0, 1): the
    /// resampling targets use an exponential moving average of the adjoints (0: this
    /// iteration's adjoint, as the values do), so that they change less between iterations
    /// than a noisy primal's adjoint does. The values, and so the estimate, always use the
    /// iteration's own adjoint. `None`: by the primal estimator, [`TARGET_SMOOTHING_INDEPENDENT`]
    /// with the independent primal and 0 with the control variate, whose image is already a
    /// recursive average (a second one only adds lag: measured worse on `vase` and `sphere`).
    pub target_smoothing: Option<f32>,
    /// Reuse on a schedule: the kept samples' confidence cap is `m_cap` times the
    /// learning-rate schedule's factor at the iteration (so with a decaying schedule early
    /// iterations reuse fully and late ones average mostly fresh samples); without a schedule
    /// it changes nothing.
    pub m_cap_follows_schedule: bool,
    /// Entries of the claim log, which lets the winners of each iteration's races write their
    /// paths without tracing the samples again (`restir_claim.wgsl`). `None`: sized from the
    /// task (at most one per reservoir; docs/method.md). An iteration that fills it traces
    /// its samples a second time instead (counted as claims overflowed); nothing is lost.
    pub claim_entries: Option<u32>,
    /// Report the variance of each texel's estimate to the step (`Estimator::variance`): a
    /// moving variance of the fresh candidates' own estimate, scaled by the share the merge
    /// gives them (docs/method.md). Without it the variance-scaled step keeps a moving
    /// variance of the merged estimates, whose kept samples repeat for many iterations.
    /// Off by default: measured with the variance-scaled step (30 s, lavapipe), it lowered
    /// `atelier`'s texture error (1.14x to 1.07x the baseline with Adam's unfiltered, 1.03x
    /// to 1.00x filtered) and raised `gallery`'s (0.62x to 0.65x unfiltered, 0.41x to 0.52x
    /// filtered).
    pub own_variance: bool,
}

impl Default for RestirOptions {
    fn default() -> Self {
        RestirOptions {
            m_cap: 8.0,
            confidence: Confidence::default(),
            temporal: true,
            positivization: true,
            verify_paths: false,
            target_smoothing: None,
            m_cap_follows_schedule: false,
            claim_entries: None,
            own_variance: false,
        }
    }
}

impl RestirOptions {
    /// The target smoothing used with the primal estimator `primal`.
    pub fn target_smoothing_for(&self, primal: crate::optim::PrimalMode) -> f32 {
        self.target_smoothing.unwrap_or(match primal {
            crate::optim::PrimalMode::Independent => TARGET_SMOOTHING_INDEPENDENT,
            crate::optim::PrimalMode::ControlVariate => 0.0,
        })
    }
}

/// [`RestirOptions::target_smoothing`] by default with the independent primal.
pub const TARGET_SMOOTHING_INDEPENDENT: f32 = 0.9;
