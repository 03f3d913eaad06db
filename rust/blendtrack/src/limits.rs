//! Size limits on what user input may make the core allocate.
//!
//! Memory sized by a number the user typed (a duration, a step, a delay, a
//! track length) is checked against these bounds *before* anything is
//! allocated, so a mistyped `1e8` is an error naming the value and the limit,
//! never an allocation failure that aborts the process.

/// Most steps one [`crate::sim::simulate`] run may record: 5 million steps
/// (14 columns of f64, about 560 MB), e.g. 13.9 simulated hours at dt = 0.01 s.
pub const MAX_SIM_STEPS: usize = 5_000_000;

/// Most vertices a path generator ([`crate::Path::straight`],
/// [`crate::Path::test_track`]) may produce (about 400 MB of path tables).
pub const MAX_PATH_POINTS: usize = 5_000_000;

/// Largest coordinate magnitude (m) of a path vertex or a vehicle position.
/// At 1e9 m an f64 still resolves 0.12 micrometres; far beyond it, offsets of
/// metres vanish in rounding (a track scaled by 1e300 would report a 4 m
/// offset as 0 error), so larger coordinates are refused, not run.
pub const MAX_COORDINATE_M: f64 = 1e9;

/// `v` readably in a message: plain for ordinary magnitudes, scientific
/// (`1e300`, `1e-300`) for huge or tiny ones, never 300 digits.
pub fn fmt_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e6).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// `value` (a count computed from user input, possibly huge, inf or NaN) as a
/// usize when it is at most `limit`; `None` otherwise.
pub fn count_within(value: f64, limit: usize) -> Option<usize> {
    if value.is_finite() && value >= 0.0 && value <= limit as f64 {
        Some(value as usize)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_beyond_the_limit_or_not_finite_are_refused() {
        assert_eq!(count_within(0.0, 10), Some(0));
        assert_eq!(count_within(10.0, 10), Some(10));
        assert_eq!(count_within(10.5, 10), None);
        assert_eq!(count_within(1e300, 10), None);
        assert_eq!(count_within(f64::INFINITY, 10), None);
        assert_eq!(count_within(f64::NAN, 10), None);
        assert_eq!(count_within(-1.0, 10), None);
    }

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(fmt_number(0.01), "0.01");
        assert_eq!(fmt_number(1e300), "1e300");
        assert_eq!(fmt_number(-1e-300), "-1e-300");
        assert_eq!(fmt_number(4e9), "4e9");
        assert_eq!(fmt_number(f64::NAN), "NaN");
    }
}
