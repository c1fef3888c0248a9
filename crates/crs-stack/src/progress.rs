//! How a long library step (identification, surrogate fit, campaign recording) shows that it
//! runs: the command line draws a spinner, tests and other callers pass [`Silent`].

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
