//! Warm-up before timed frames.

use anyhow::Result;
use std::time::{Duration, Instant};

/// How long to run untimed frames before timing: pipelines compile and buffers grow on first
/// use, and a GPU left idle while the host worked (a tradeoff row's comparisons, say) runs at
/// lower clocks until it has been busy for a while. On the H200 a fixed three frames of 2 ms
/// were not enough: the rows `splat tradeoff` timed later read up to 2.5x slower than the
/// same work timed first.
const WARM_UP: Duration = Duration::from_millis(300);

/// Runs `frame` at least once, and until `WARM_UP` has passed.
pub(crate) fn warm_up<T>(mut frame: impl FnMut() -> Result<T>) -> Result<()> {
    let start = Instant::now();
    frame()?;
    while start.elapsed() < WARM_UP {
        frame()?;
    }
    Ok(())
}
