//! Progress bars and the lines printed above them.

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

/// The progress bars of one command, with lines printed above them (or to
/// standard error when the output is not a terminal and the bars are
/// hidden).
#[derive(Clone, Debug, Default)]
pub struct Progress {
    bars: MultiProgress,
}

impl Progress {
    pub fn new() -> Progress {
        Progress::default()
    }

    /// Prints `line` above the bars.
    pub fn say(&self, line: impl Into<String>) {
        let line = line.into();
        if self.bars.is_hidden() || self.bars.println(&line).is_err() {
            eprintln!("{line}");
        }
    }

    /// A bar for one task, labelled `label`, its length set by the task.
    pub fn task(&self, label: &str) -> ProgressBar {
        let bar = self.bars.add(ProgressBar::new(0));
        bar.set_style(
            ProgressStyle::with_template(
                "{msg:>24} [{elapsed_precise}] {wide_bar} {percent}% eta {eta}",
            )
            .expect("valid template"),
        );
        bar.set_message(label.to_string());
        bar
    }

    /// A bar counting `total` runs.
    pub fn runs(&self, total: usize) -> ProgressBar {
        let bar = self.bars.add(ProgressBar::new(total as u64));
        bar.set_style(
            ProgressStyle::with_template(
                "{msg:>40} [{elapsed_precise}] {wide_bar} {pos}/{len} runs",
            )
            .expect("valid template"),
        );
        bar
    }
}
