//! How a long library step (identification, surrogate fit, campaign recording) shows that it
//! runs: the command line draws a [`Spinner`], tests and other callers pass [`Silent`].

/// Progress of one step at a time: `start`, any number of `update`s, `finish`.
pub trait Progress {
    fn start(&mut self, what: &str);
    fn update(&mut self, what: String);
    fn finish(&mut self);
}

/// No progress shown.
pub struct Silent;

impl Progress for Silent {
    fn start(&mut self, _what: &str) {}
    fn update(&mut self, _what: String) {}
    fn finish(&mut self) {}
}

/// A spinner with the elapsed time and the step's message on stderr (the command line's).
#[derive(Default)]
pub struct Spinner(Option<indicatif::ProgressBar>);

impl Progress for Spinner {
    fn start(&mut self, what: &str) {
        let bar = indicatif::ProgressBar::new_spinner();
        bar.set_style(
            indicatif::ProgressStyle::with_template("{spinner} [{elapsed}] {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        bar.enable_steady_tick(std::time::Duration::from_millis(120));
        bar.set_message(what.to_string());
        self.0 = Some(bar);
    }
    fn update(&mut self, what: String) {
        if let Some(b) = &self.0 {
            b.set_message(what);
        }
    }
    fn finish(&mut self) {
        if let Some(b) = self.0.take() {
            b.finish_and_clear();
        }
    }
}
