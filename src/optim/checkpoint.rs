//! Checkpoints: everything needed to continue a run exactly where it stopped (iteration,
//! elapsed time, textures, Adam moments, the metrics so far; the random numbers are a pure
//! function of seed and iteration). Written atomically: a temporary file, then a rename.
use crate::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: &[u8; 8] = b"PSRCKPT1";

/// One row of metrics.csv.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetricRow {
    /// Iterations done.
    pub iteration: u32,
    /// Optimization time so far (seconds, target rendering excluded).
    pub elapsed_s: f64,
    /// Loss of the iteration's primal render.
    pub loss: f64,
    /// RMSE of the textures against the ground truth (linear values), when known.
    pub texture_rmse: Option<f64>,
}

/// Small fields, stored as a JSON header.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Iterations done.
    pub iteration: u32,
    /// Optimization time so far.
    pub elapsed_s: f64,
    /// What the textures are (names and sizes); a resume must match it.
    pub layout: String,
    /// Number of floats in each array.
    pub n_params: usize,
    /// Metrics so far.
    pub metrics: Vec<MetricRow>,
}

/// A whole checkpoint.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Header.
    pub header: Header,
    /// Texture values.
    pub params: Vec<f32>,
    /// Adam first moments.
    pub m1: Vec<f32>,
    /// Adam second moments.
    pub m2: Vec<f32>,
}

impl Checkpoint {
    /// Write atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let header =
            serde_json::to_vec(&self.header).map_err(|e| Error::file(path, e.to_string()))?;
        let mut out = Vec::with_capacity(16 + header.len() + 12 * self.params.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        for a in [&self.params, &self.m1, &self.m2] {
            out.extend_from_slice(bytemuck::cast_slice(a));
        }
        crate::image_io::write_atomic(path, &out)
    }

    /// Read and check.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
        let bad = |m: &str| Error::file(path, format!("not a psrestir checkpoint: {m}"));
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad("wrong magic"));
        }
        let hlen = u64::from_le_bytes(bytes[8..16].try_into().map_err(|_| bad("short"))?) as usize;
        let hend = 16usize
            .checked_add(hlen)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| bad("truncated header"))?;
        let header: Header =
            serde_json::from_slice(&bytes[16..hend]).map_err(|e| bad(&e.to_string()))?;
        let n = header.n_params;
        if bytes.len() != hend + 12 * n {
            return Err(bad("truncated data"));
        }
        let arr = |k: usize| -> Vec<f32> {
            bytemuck::pod_collect_to_vec(&bytes[hend + 4 * n * k..hend + 4 * n * (k + 1)])
        };
        Ok(Checkpoint {
            params: arr(0),
            m1: arr(1),
            m2: arr(2),
            header,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_truncation_is_detected() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.bin");
        let c = Checkpoint {
            header: Header {
                iteration: 7,
                elapsed_s: 1.5,
                layout: "x".into(),
                n_params: 3,
                metrics: vec![MetricRow {
                    iteration: 1,
                    elapsed_s: 0.1,
                    loss: 2.0,
                    texture_rmse: None,
                }],
            },
            params: vec![1.0, 2.0, 3.0],
            m1: vec![0.1; 3],
            m2: vec![0.2; 3],
        };
        c.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 1]).unwrap();
        assert!(Checkpoint::load(&p)
            .unwrap_err()
            .to_string()
            .contains("truncated"));
    }
}
