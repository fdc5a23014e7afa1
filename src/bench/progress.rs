//! The bench's progress: a bar over the phases of all scenes, or log lines without one.

/// Progress reporting: a bar over the phases of all scenes.
pub(super) struct Progress {
    pub(super) bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    pub(super) fn new(enabled: bool, phases: u64) -> Progress {
        let bar = enabled.then(|| {
            let b = indicatif::ProgressBar::new(phases);
            b.set_style(
                indicatif::ProgressStyle::with_template(
                    "bench [{bar:30}] {pos}/{len} {msg} ({elapsed})",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
            );
            b
        });
        Progress { bar }
    }
    pub(super) fn message(&self, m: String) {
        match &self.bar {
            Some(b) => b.set_message(m),
            None => log::info!("{m}"),
        }
    }
    pub(super) fn done(&self) {
        if let Some(b) = &self.bar {
            b.inc(1);
        }
    }
    pub(super) fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }
}
