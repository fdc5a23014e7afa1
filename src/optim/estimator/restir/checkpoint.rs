//! ReSTIR's state in a checkpoint: the kept reservoirs of every observed texel (wherever
//! their headers point), the target adjoints, the counters, and the fresh estimates' moments
//! where `own_variance` tracks them; and their return to the GPU buffers.
use super::{reservoir, state_names, Restir};
use crate::gpu::Gpu;
use crate::optim::estimator::{EstimatorState, Method};
use crate::{Error, Result};

impl Restir {
    /// The estimator's state, read back from the GPU
    /// ([`Estimator::snapshot`](crate::optim::estimator::Estimator::snapshot)).
    pub(super) fn save(&self, gpu: &Gpu) -> Result<EstimatorState> {
        // The kept reservoirs, sign 0 then sign 1 of each observed texel, wherever they lie.
        let slots = self
            .slots
            .iter()
            .map(|b| gpu.read_pod::<u32>(b))
            .collect::<Result<Vec<_>>>()?;
        let headers: Vec<u32> = gpu.read_pod(&self.headers)?;
        let n_observed = self.merge_params.n_observed as usize;
        let mut state = EstimatorState::new(Method::RESTIR);
        state.counters = vec![
            (state_names::HISTORY.into(), self.history),
            (state_names::WORDS.into(), self.words),
            (state_names::MOMENT_UPDATES.into(), self.moment_updates),
        ];
        state.arrays = vec![
            (
                state_names::RESERVOIRS.into(),
                kept_reservoirs(&slots, &headers[..n_observed], self.words),
            ),
            (state_names::TARGETS.into(), gpu.read_pod(&self.targets)?),
            // Empty where they are not tracked (`own_variance` off).
            (
                state_names::FRESH_MOMENTS.into(),
                if self.options.own_variance {
                    gpu.read_pod(&self.fresh_moments)?
                } else {
                    Vec::new()
                },
            ),
        ];
        Ok(state)
    }

    /// Write `state` (or, for `None` or an empty one, a fresh start) into the GPU buffers
    /// ([`Estimator::restore`](crate::optim::estimator::Estimator::restore)).
    pub(super) fn load(&mut self, gpu: &Gpu, state: Option<&EstimatorState>) -> Result<()> {
        let zeros = vec![0u32; self.fresh_moments.size() as usize / 4];
        let kept = match state.filter(|r| !r.arrays.is_empty()) {
            Some(r) => {
                let saved = self.checked(r, &zeros)?;
                gpu.queue
                    .write_buffer(&self.targets, 0, bytemuck::cast_slice(saved.targets));
                gpu.queue
                    .write_buffer(&self.fresh_moments, 0, bytemuck::cast_slice(saved.moments));
                self.history = if self.options.temporal {
                    saved.history
                } else {
                    0
                };
                self.moment_updates = saved.moment_updates;
                saved.reservoirs.to_vec()
            }
            None => {
                // The first iteration forms the target adjoint from its own adjoint alone.
                self.history = 0;
                self.moment_updates = 0;
                gpu.queue
                    .write_buffer(&self.fresh_moments, 0, bytemuck::cast_slice(&zeros));
                vec![0; self.merge_params.n_observed as usize * 2 * self.words as usize]
            }
        };
        let (slots, headers) = slots_holding(&kept, self.words);
        for (buffer, words) in self.slots.iter().zip(&slots) {
            if !words.is_empty() {
                gpu.queue
                    .write_buffer(buffer, 0, bytemuck::cast_slice(words));
            }
        }
        if !headers.is_empty() {
            gpu.queue
                .write_buffer(&self.headers, 0, bytemuck::cast_slice(&headers));
        }
        Ok(())
    }

    /// The parts of a saved state `r`, checked against this optimizer's sizes; the fresh
    /// moments are `zeros` where they are not tracked now, or were not then.
    fn checked<'a>(&self, r: &'a EstimatorState, zeros: &'a [u32]) -> Result<Saved<'a>> {
        let missing = |name: &str| Error::Invalid(format!("the saved ReSTIR state has no {name}"));
        let array = |name: &str| r.array(name).ok_or_else(|| missing(name));
        let counter = |name: &str| r.counter(name).ok_or_else(|| missing(name));
        let (reservoirs, targets) = (
            array(state_names::RESERVOIRS)?,
            array(state_names::TARGETS)?,
        );
        let (moments, history) = (
            array(state_names::FRESH_MOMENTS)?,
            counter(state_names::HISTORY)?,
        );
        let moment_updates = counter(state_names::MOMENT_UPDATES)?;
        // Not tracked now: nothing to restore. Saved without them (`own_variance` off then):
        // they start afresh, as in a new run.
        let (moments, moment_updates) = if !self.options.own_variance {
            (zeros, moment_updates)
        } else if moments.is_empty() {
            (zeros, 0)
        } else {
            (moments, moment_updates)
        };
        if moments.len() as u64 * 4 != self.fresh_moments.size() {
            return Err(Error::Invalid(format!(
                "the saved ReSTIR state has {} fresh-moment words where this optimizer's \
                 textures need {}: it was saved for other textures",
                moments.len(),
                self.fresh_moments.size() / 4
            )));
        }
        let words = r.counter(state_names::WORDS).unwrap_or(0);
        if words != self.words {
            return Err(Error::Invalid(format!(
                "the saved ReSTIR state has reservoirs of {words} words, this version of \
                 psrestir keeps {} at this path depth: start afresh (without --resume)",
                self.words
            )));
        }
        let n_observed = self.merge_params.n_observed as usize;
        let expected = n_observed * 2 * self.words as usize;
        if reservoirs.len() != expected {
            return Err(Error::Invalid(format!(
                "the saved ReSTIR state has {} words where this optimizer keeps {expected} \
                 ({n_observed} observed texels x 2 reservoirs x {} words): it was saved for \
                 other textures or cameras",
                reservoirs.len(),
                self.words
            )));
        }
        if targets.len() as u64 * 4 != self.targets.size() {
            return Err(Error::Invalid(format!(
                "the saved ReSTIR state has {} target-adjoint floats where this optimizer's \
                 images need {}",
                targets.len(),
                self.targets.size() / 4
            )));
        }
        Ok(Saved {
            reservoirs,
            targets,
            moments,
            history,
            moment_updates,
        })
    }
}

/// A saved ReSTIR state's parts, checked against the optimizer that restores it.
struct Saved<'a> {
    reservoirs: &'a [u32],
    targets: &'a [u32],
    moments: &'a [u32],
    history: u32,
    moment_updates: u32,
}

/// The kept reservoirs (two per observed texel, sign 0 then sign 1) that `headers` point at
/// in `slots` (slot k of every observed texel in `slots[k]`), `words` words each.
fn kept_reservoirs(slots: &[Vec<u32>], headers: &[u32], words: u32) -> Vec<u32> {
    let words = words as usize;
    let mut out = Vec::with_capacity(headers.len() * 2 * words);
    for (i, &h) in headers.iter().enumerate() {
        for sign in 0..2 {
            let k = reservoir::header_slot(h, sign) as usize;
            out.extend_from_slice(&slots[k][i * words..(i + 1) * words]);
        }
    }
    out
}

/// Slots and headers that hold `kept` (two reservoirs per observed texel) in slots 0 and 1,
/// with slots 2 and 3 free, `words` words each.
fn slots_holding(kept: &[u32], words: u32) -> (Vec<Vec<u32>>, Vec<u32>) {
    let words = words as usize;
    let n = kept.len() / (2 * words);
    let mut slots = vec![vec![0; n * words]; reservoir::SLOTS as usize];
    for i in 0..n {
        for (sign, slot) in slots.iter_mut().take(2).enumerate() {
            let src = (2 * i + sign) * words;
            slot[i * words..(i + 1) * words].copy_from_slice(&kept[src..src + words]);
        }
    }
    (slots, vec![reservoir::HEADER_FIRST_TWO; n])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kept_reservoirs_follow_the_headers() {
        let words = reservoir::WORDS as usize;
        // Two observed texels whose reservoirs are numbered by (texel, sign).
        let kept: Vec<u32> = (0..2 * 2 * words as u32).collect();
        let (mut slots, mut headers) = slots_holding(&kept, reservoir::WORDS);
        assert_eq!(kept_reservoirs(&slots, &headers, reservoir::WORDS), kept);
        // Texel 1's reservoirs move to slots 3 (sign 0) and 2 (sign 1), as a merge that
        // selected its fresh samples leaves them.
        let r = words..2 * words;
        let (s0, s1) = (slots[0][r.clone()].to_vec(), slots[1][r.clone()].to_vec());
        slots[3][r.clone()].copy_from_slice(&s0);
        slots[2][r.clone()].copy_from_slice(&s1);
        slots[0][r.clone()].fill(0);
        slots[1][r].fill(0);
        headers[1] = 3 | (2 << reservoir::HEADER_SLOT_BITS);
        assert_eq!(reservoir::header_slot(headers[1], 0), 3);
        assert_eq!(reservoir::header_slot(headers[1], 1), 2);
        assert_eq!(kept_reservoirs(&slots, &headers, reservoir::WORDS), kept);
    }
}
