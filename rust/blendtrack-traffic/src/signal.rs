//! Traffic-light and right-of-way states at stop lines: [`Signal`], its
//! mapping from SUMO's link state characters, and the light table look-up.

use crate::route::StopLine;

/// What a stop line's signal (or the road's right of way) says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Signal {
    /// Red, or red-yellow: stop.
    Stop = 0,
    /// Yellow: stop if that is comfortably possible, else clear the junction.
    Yellow = 1,
    /// Green with priority, or a major road: go.
    Priority = 2,
    /// Go but give way (green without priority, a minor road, a light that
    /// is off or blinking): wait while the simulator reports foes.
    Yield = 3,
}

impl Signal {
    /// The signal of a SUMO link state character (`r`, `y`, `G`, `g`, ...).
    pub fn from_sumo(c: u8) -> Signal {
        match c {
            b'r' | b'R' | b'u' => Signal::Stop,
            b'y' | b'Y' => Signal::Yellow,
            b'G' | b'M' => Signal::Priority,
            _ => Signal::Yield,
        }
    }
}

/// Lights are numbered below this.
pub(crate) const MAX_LIGHTS: usize = 1 << 20;

/// The signal at a stop line, from the light table (a free function, so the
/// step loop can borrow a vehicle mutably meanwhile). A light never reported
/// counts as green with priority, as the simulator without the light would.
pub(crate) fn signal_at(signals: &[Vec<Signal>], stop: &StopLine) -> Signal {
    match stop.signal {
        Some((light, link)) => signals
            .get(light)
            .and_then(|l| l.get(link))
            .copied()
            .unwrap_or(Signal::Priority),
        None if stop.major => Signal::Priority,
        None => Signal::Yield,
    }
}
