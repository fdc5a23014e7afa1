//! What the optimizer measures of its own work: GPU time per kind of pass, from timestamp
//! queries, and the values its passes dropped or lost.

use crate::gpu::Gpu;
use crate::Result;

/// The kinds of pass that timestamp queries time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PassKind {
    Primal,
    Loss,
    Gradient,
    Combine,
    Prior,
    Step,
    Filter,
}

/// GPU milliseconds of each kind of pass in the last iteration (from timestamp queries).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PassTimes {
    /// Primal renders of all cameras.
    pub primal_ms: f64,
    /// Loss and adjoint.
    pub loss_ms: f64,
    /// The estimator's sampling passes (the baseline's gradient, ReSTIR's candidates, the
    /// recursive estimator's gradient).
    pub gradient_ms: f64,
    /// The estimator's pass that combines the iteration's samples with what it kept
    /// (ReSTIR's merge, the recursive estimator's combination), if it has one.
    pub combine_ms: f64,
    /// The priors' passes (smoothness, multiscale gradient), when they are on.
    pub prior_ms: f64,
    /// The step (Adam or the variance step; with the moment filter, both of its phases).
    pub step_ms: f64,
    /// The moment filter's levels, when it is on.
    pub filter_ms: f64,
}

impl PassTimes {
    /// Add `other` pass by pass.
    pub fn add(&mut self, other: &PassTimes) {
        self.primal_ms += other.primal_ms;
        self.loss_ms += other.loss_ms;
        self.gradient_ms += other.gradient_ms;
        self.combine_ms += other.combine_ms;
        self.prior_ms += other.prior_ms;
        self.step_ms += other.step_ms;
        self.filter_ms += other.filter_ms;
    }

    /// Every pass divided by `n` (the mean of `n` added iterations).
    pub fn divided(&self, n: f64) -> PassTimes {
        PassTimes {
            primal_ms: self.primal_ms / n,
            loss_ms: self.loss_ms / n,
            gradient_ms: self.gradient_ms / n,
            combine_ms: self.combine_ms / n,
            prior_ms: self.prior_ms / n,
            step_ms: self.step_ms / n,
            filter_ms: self.filter_ms / n,
        }
    }

    /// All passes together.
    pub fn total(&self) -> f64 {
        self.primal_ms
            + self.loss_ms
            + self.gradient_ms
            + self.combine_ms
            + self.prior_ms
            + self.step_ms
            + self.filter_ms
    }
}

/// Timestamp queries around the passes of one iteration, where the device has them: each
/// pass asks for the next begin/end pair with [`PassTimer::next`], naming its kind.
pub(crate) struct PassTimer {
    queries: Option<(wgpu::QuerySet, wgpu::Buffer)>,
    capacity: u32,
    kinds: Vec<PassKind>,
}

impl PassTimer {
    pub(super) fn new(gpu: &Gpu, capacity: u32) -> PassTimer {
        let queries = gpu.timestamps.then(|| {
            let n = 2 * capacity;
            (
                gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("pass timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: n,
                }),
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("pass timestamps resolve"),
                    size: 8 * n as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
            )
        });
        PassTimer {
            queries,
            capacity,
            kinds: Vec::new(),
        }
    }

    pub(super) fn begin(&mut self) {
        self.kinds.clear();
    }

    /// The query pair of the next pass, of kind `kind` (None without timestamps).
    pub(crate) fn next(&mut self, kind: PassKind) -> Option<(&wgpu::QuerySet, u32)> {
        let (q, _) = self.queries.as_ref()?;
        let k = self.kinds.len() as u32;
        if k >= self.capacity {
            return None;
        }
        self.kinds.push(kind);
        Some((q, k))
    }

    pub(super) fn resolve(&self, enc: &mut wgpu::CommandEncoder) {
        if let Some((q, buf)) = &self.queries {
            if !self.kinds.is_empty() {
                enc.resolve_query_set(q, 0..2 * self.kinds.len() as u32, buf, 0);
            }
        }
    }

    pub(super) fn read(&self, gpu: &Gpu) -> Result<Option<PassTimes>> {
        let Some((_, buf)) = &self.queries else {
            return Ok(None);
        };
        let ticks: Vec<u64> = gpu.read_pod(buf)?;
        let period = gpu.queue.get_timestamp_period() as f64 * 1e-6;
        let mut t = PassTimes::default();
        for (k, kind) in self.kinds.iter().enumerate() {
            let ms = ticks[2 * k + 1].saturating_sub(ticks[2 * k]) as f64 * period;
            match kind {
                PassKind::Primal => t.primal_ms += ms,
                PassKind::Loss => t.loss_ms += ms,
                PassKind::Gradient => t.gradient_ms += ms,
                PassKind::Combine => t.combine_ms += ms,
                PassKind::Prior => t.prior_ms += ms,
                PassKind::Step => t.step_ms += ms,
                PassKind::Filter => t.filter_ms += ms,
            }
        }
        Ok(Some(t))
    }
}

/// Counters of dropped or lost values since the optimizer was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Gradient additions that exhausted the compare-and-swap bound.
    pub lost_updates: u32,
    /// Non-finite values dropped by the gradient or candidate pass.
    pub dropped_gradient: u32,
    /// Non-finite gradients the step skipped (their parameter left unchanged).
    pub skipped_step: u32,
    /// Non-finite primal samples dropped.
    pub dropped_primal: u32,
    /// Pixels whose loss or adjoint was not finite (e.g. a NaN in the target), counted once
    /// per iteration and camera, and left out of the loss and the gradient.
    pub dropped_pixels: u32,
    /// Samples an estimator could not keep because an atomic update ran out of tries
    /// (ReSTIR's candidates whose weight was not added to a reservoir's sum; gradient
    /// additions the candidate pass gave up on).
    pub lost_kept: u32,
    /// Non-finite values of kept samples an estimator dropped when it used them again
    /// (ReSTIR's stored paths in the merge).
    pub dropped_kept: u32,
}
