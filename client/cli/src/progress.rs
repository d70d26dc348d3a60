//! The command line's progress bar (bakes made for a method, `bspvt-server bake`'s style).

use indicatif::{ProgressBar, ProgressStyle};

/// A vertex-count bar on stderr; its length is set by the first update.
pub(crate) fn progress_bar() -> ProgressBar {
    ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} vertices  {per_sec}  elapsed {elapsed_precise}  ETA {eta_precise}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    )
}
