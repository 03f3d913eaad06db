//! Batch control of many vehicles in one call per step (a traffic bridge's unit).
//!
//! A [`Fleet`] keeps a registry of tracks (a path plus its virtual corridor,
//! e.g. one per road route) and of vehicles, each in a numbered slot with its
//! own [`Controller`] (projection hints), configuration and vehicle limits.
//! Vehicles come and go: [`Fleet::add_vehicle`] returns a slot number,
//! [`Fleet::remove_vehicle`] frees it, and a freed number is handed out again
//! by a later `add_vehicle` (lowest first), so callers map their own ids to
//! slots and drop the mapping on removal.
//!
//! [`Fleet::step`] takes column arrays (one entry per listed slot, in any
//! order): the measured state, an optional per-vehicle blend factor and the
//! real obstacles (leader gap and speed, stop-line gap), and returns column
//! arrays of commands and errors. With a time step it also integrates each
//! vehicle's next state through the kinematic bicycle with its actuator
//! limits (no delay line: the caller owns time), for callers that let
//! blendtrack move the vehicles.
//!
//! Error policy (two levels, so one bad vehicle never spoils the others):
//! - Errors of the CALL, detected before anything is stepped, reject the
//!   whole step and change nothing: arrays of the wrong length (the error
//!   names the argument), a slot that is not in use or appears twice (the
//!   error names it), a non-positive or non-finite `dt`.
//! - Errors of ONE VEHICLE's data: a non-finite state component or an alpha
//!   outside [0, 1]. That vehicle gets `ok = false` and NaN in every output
//!   column, its controller state (projection hints) is left as it was, and
//!   every other vehicle is stepped normally.
//!
//! Obstacle columns use NaN or +inf for "none". A leader with a finite gap but
//! a NaN speed is taken as standing still (the conservative reading).
//! A NaN alpha means "use the vehicle's configured `lat_blend_factor`".

use crate::config::{validate_vehicle, ControllerConfig};
use crate::controller::{ControlOutput, Controller, Track};
use crate::error::ConfigError;
use crate::longitudinal::Obstacle;
use crate::path::Path;
use crate::vehicle::{advance, Command, HeadingTrig, VehicleParams, VehicleState};
use std::mem::MaybeUninit;
use std::sync::Arc;
use thiserror::Error;

/// An error of a whole fleet call (see the module docs for the policy).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FleetError {
    #[error("argument `{argument}` has {got} entries, expected {expected} (one per slot)")]
    Length {
        argument: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("slot {slot} is not in use (never added, or removed)")]
    UnknownSlot { slot: i64 },
    #[error("slot {slot} appears more than once in one step")]
    DuplicateSlot { slot: i64 },
    #[error("track id {track_id} is not registered (never added, or removed)")]
    UnknownTrack { track_id: i64 },
    #[error(
        "track id {track_id} is still driven by slot {slot}: move or remove the vehicle first"
    )]
    TrackInUse { track_id: i64, slot: i64 },
    #[error("argument `{name}` = {value}: {message}")]
    Parameter {
        name: &'static str,
        value: f64,
        message: &'static str,
    },
    #[error(transparent)]
    Config(#[from] ConfigError),
}

/// One step's inputs: column arrays, entry `i` belongs to `slots[i]`.
#[derive(Debug, Clone, Copy)]
pub struct FleetInputs<'a> {
    pub slots: &'a [i64],
    pub x_m: &'a [f64],
    pub y_m: &'a [f64],
    pub theta_rad: &'a [f64],
    /// Signed speed (m/s, < 0 backwards).
    pub v_mps: &'a [f64],
    pub delta_rad: &'a [f64],
    /// Blend factor per vehicle (NaN = the vehicle's configured one).
    pub alpha: Option<&'a [f64]>,
    /// Gap to the leader along the path (m; NaN/inf = no leader).
    pub leader_gap_m: Option<&'a [f64]>,
    /// Leader speed along the direction of travel (m/s).
    pub leader_speed_mps: Option<&'a [f64]>,
    /// The stopping law's reaction time for the leader (s; NaN = the
    /// vehicle's `reaction_time`): see [`Obstacle::reaction_s`].
    pub leader_reaction_s: Option<&'a [f64]>,
    /// Gap to a stop line (m; NaN/inf = none).
    pub stop_gap_m: Option<&'a [f64]>,
    /// Gap to a vehicle to line up behind (m; NaN/inf = none): a soft
    /// obstacle ([`Obstacle::soft`]), braked for at `max_deceleration` at most.
    pub soft_gap_m: Option<&'a [f64]>,
    /// Its speed along the direction of travel (m/s; NaN = standing).
    pub soft_speed_mps: Option<&'a [f64]>,
    /// Speed limit where the vehicle is (m/s; NaN/inf = none): the free-flow
    /// law aims at `min(preferred_speed, limit)`.
    pub speed_limit_mps: Option<&'a [f64]>,
    /// When given, the next state is integrated over this time step (s).
    pub dt_s: Option<f64>,
}

impl<'a> FleetInputs<'a> {
    /// Inputs with no alpha, obstacles or time step.
    pub fn new(
        slots: &'a [i64],
        x_m: &'a [f64],
        y_m: &'a [f64],
        theta_rad: &'a [f64],
        v_mps: &'a [f64],
        delta_rad: &'a [f64],
    ) -> Self {
        FleetInputs {
            slots,
            x_m,
            y_m,
            theta_rad,
            v_mps,
            delta_rad,
            alpha: None,
            leader_gap_m: None,
            leader_speed_mps: None,
            leader_reaction_s: None,
            stop_gap_m: None,
            soft_gap_m: None,
            soft_speed_mps: None,
            speed_limit_mps: None,
            dt_s: None,
        }
    }
}

/// One step's outputs, one entry per input slot, in the input order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FleetOutputs {
    /// False where the vehicle's inputs were unusable (its outputs are NaN).
    pub ok: Vec<bool>,
    pub steering_rad: Vec<f64>,
    /// Acceleration command along the direction of travel (before vehicle limits).
    pub accel_mps2: Vec<f64>,
    /// Blend factor used.
    pub alpha: Vec<f64>,
    /// Errors of the control point P(alpha).
    pub lateral_error_m: Vec<f64>,
    pub heading_error_rad: Vec<f64>,
    pub s_m: Vec<f64>,
    /// Arc length of the rear axle's foot point.
    pub s_rear_m: Vec<f64>,
    /// Signed lateral errors of the rear and the front axle (fixed points).
    pub lateral_error_rear_m: Vec<f64>,
    pub lateral_error_front_m: Vec<f64>,
    pub curvature_per_m: Vec<f64>,
    /// Distance to the virtual obstacle (m, +inf on free road).
    pub virtual_obstacle_m: Vec<f64>,
    /// The integrated next state, when a time step was given.
    pub next: Option<NextStates>,
}

/// Next states after `dt` (columns; NaN where `ok` is false).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NextStates {
    pub x_m: Vec<f64>,
    pub y_m: Vec<f64>,
    pub theta_rad: Vec<f64>,
    pub v_mps: Vec<f64>,
    pub delta_rad: Vec<f64>,
}

#[derive(Debug, Clone)]
struct Entry {
    track_id: usize,
    controller: Controller,
    params: VehicleParams,
    /// The sine and cosine of the heading the last step integrated (before
    /// wrapping): a caller that feeds the next state back as the next
    /// step's input gives that heading, whose sine and cosine are then not
    /// taken again.
    next_trig: Option<HeadingTrig>,
}

#[derive(Debug, Clone)]
struct TrackEntry {
    track: Arc<Track>,
    config: ControllerConfig,
}

/// Tracks and vehicles stepped together (see the module docs).
#[derive(Debug, Clone, Default)]
pub struct Fleet {
    /// By id; None once removed (the id is handed out again, lowest first).
    tracks: Vec<Option<TrackEntry>>,
    slots: Vec<Option<Entry>>,
    n_active: usize,
    /// Per slot: [`FREE`] when not in use, else the last step that listed
    /// it (its `epoch`). A step's check reads this small array, not the
    /// slots' entries (552 bytes each), and needs no allocation.
    marks: Vec<u32>,
    /// The number of the current step (never `FREE`).
    epoch: u32,
    /// Threads a large step is split over (0: rayon's global pool, one per core).
    threads: usize,
    /// The pool of `threads` threads when more than one is asked for.
    pool: Option<Arc<rayon::ThreadPool>>,
}

impl Fleet {
    pub fn new() -> Self {
        Self::default()
    }

    /// Threads a step of at least `PARALLEL_MIN_VEHICLES` vehicles is split
    /// over: 0 (the default) for one per core (rayon's global pool), 1 to
    /// stay on the calling thread, more for a pool of that many (at most
    /// `MAX_THREADS`; a pool the system cannot start falls back to the
    /// global one).
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads;
        self.pool = (threads > 1)
            .then(|| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads.min(MAX_THREADS))
                    .build()
                    .ok()
            })
            .flatten()
            .map(Arc::new);
    }
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Registers a track; `config` builds its corridor and is the default
    /// configuration of the vehicles added to it. Returns the track id: the
    /// lowest id free (a removed track's is handed out again, as slots are),
    /// so the registry stays as large as the most tracks registered at once.
    pub fn add_track(&mut self, path: Path, config: ControllerConfig) -> Result<usize, FleetError> {
        config.validate()?;
        let entry = Some(TrackEntry {
            track: Arc::new(Track::new(path, &config)),
            config,
        });
        if let Some(id) = self.tracks.iter().position(Option::is_none) {
            self.tracks[id] = entry;
            return Ok(id);
        }
        self.tracks.push(entry);
        Ok(self.tracks.len() - 1)
    }

    /// Ids in the registry, removed ones included (its memory's bound).
    pub fn track_capacity(&self) -> usize {
        self.tracks.len()
    }

    /// Tracks registered and not removed.
    pub fn n_tracks(&self) -> usize {
        self.tracks.iter().filter(|t| t.is_some()).count()
    }

    /// Removes a track no vehicle drives any more (its memory goes with
    /// it); a later `add_track` may reuse its id. A track still driven is an error naming
    /// a slot on it, and nothing changes.
    pub fn remove_track(&mut self, track_id: i64) -> Result<(), FleetError> {
        self.track_entry(track_id)?;
        let id = track_id as usize;
        if let Some(slot) = self
            .slots
            .iter()
            .position(|e| e.as_ref().is_some_and(|e| e.track_id == id))
        {
            return Err(FleetError::TrackInUse {
                track_id,
                slot: slot as i64,
            });
        }
        self.tracks[id] = None;
        Ok(())
    }

    /// The track registered under `track_id`.
    pub fn track(&self, track_id: i64) -> Result<&Arc<Track>, FleetError> {
        self.track_entry(track_id).map(|t| &t.track)
    }

    fn track_entry(&self, track_id: i64) -> Result<&TrackEntry, FleetError> {
        usize::try_from(track_id)
            .ok()
            .and_then(|i| self.tracks.get(i))
            .and_then(Option::as_ref)
            .ok_or(FleetError::UnknownTrack { track_id })
    }

    /// Adds a vehicle on a track; `config` (default: the track's) and
    /// `params` (default: [`VehicleParams::default`]) are validated. Returns
    /// its slot, the lowest free one.
    pub fn add_vehicle(
        &mut self,
        track_id: i64,
        config: Option<ControllerConfig>,
        params: Option<VehicleParams>,
    ) -> Result<usize, FleetError> {
        let t = self.track_entry(track_id)?;
        let cfg = config.unwrap_or_else(|| t.config.clone());
        let params = params.unwrap_or_default();
        validate_vehicle(&params)?;
        let controller = Controller::new(t.track.clone(), cfg, &params)?;
        let entry = Entry {
            track_id: track_id as usize,
            controller,
            params,
            next_trig: None,
        };
        let slot = match self.marks.iter().position(|&m| m == FREE) {
            Some(i) => {
                self.slots[i] = Some(entry);
                self.marks[i] = 0;
                i
            }
            None => {
                self.slots.push(Some(entry));
                self.marks.push(0);
                self.slots.len() - 1
            }
        };
        self.n_active += 1;
        Ok(slot)
    }

    /// Frees a slot.
    pub fn remove_vehicle(&mut self, slot: i64) -> Result<(), FleetError> {
        let i = self.index(slot)?;
        self.slots[i] = None;
        self.marks[i] = FREE;
        self.n_active -= 1;
        Ok(())
    }

    fn index(&self, slot: i64) -> Result<usize, FleetError> {
        usize::try_from(slot)
            .ok()
            .filter(|&i| self.slots.get(i).is_some_and(Option::is_some))
            .ok_or(FleetError::UnknownSlot { slot })
    }

    fn entry(&self, slot: i64) -> Result<&Entry, FleetError> {
        let i = self.index(slot)?;
        Ok(self.slots[i]
            .as_ref()
            .expect("index() checked the slot is in use"))
    }

    /// Number of vehicles in use.
    pub fn len(&self) -> usize {
        self.n_active
    }
    pub fn is_empty(&self) -> bool {
        self.n_active == 0
    }

    /// Slots in use, ascending.
    pub fn slots(&self) -> Vec<usize> {
        self.slots
            .iter()
            .enumerate()
            .filter_map(|(i, e)| e.as_ref().map(|_| i))
            .collect()
    }

    pub fn vehicle_track(&self, slot: i64) -> Result<usize, FleetError> {
        Ok(self.entry(slot)?.track_id)
    }
    pub fn vehicle_config(&self, slot: i64) -> Result<&ControllerConfig, FleetError> {
        Ok(self.entry(slot)?.controller.config())
    }
    pub fn vehicle_params(&self, slot: i64) -> Result<&VehicleParams, FleetError> {
        Ok(&self.entry(slot)?.params)
    }

    /// Replaces a vehicle's configuration (validated). Its projection hints
    /// are dropped (the next step searches the whole track once); the
    /// corridor stays the track's.
    pub fn set_vehicle_config(
        &mut self,
        slot: i64,
        config: ControllerConfig,
    ) -> Result<(), FleetError> {
        let i = self.index(slot)?;
        let e = self.slots[i]
            .as_mut()
            .expect("index() checked the slot is in use");
        e.controller = Controller::new(e.controller.track().clone(), config, &e.params)?;
        Ok(())
    }

    /// Moves a vehicle to another track (a lane change, a new route),
    /// keeping its configuration and limits; its projection hints start over.
    pub fn set_vehicle_track(&mut self, slot: i64, track_id: i64) -> Result<(), FleetError> {
        let track = self.track_entry(track_id)?.track.clone();
        let i = self.index(slot)?;
        let e = self.slots[i]
            .as_mut()
            .expect("index() checked the slot is in use");
        e.controller = Controller::new(track, e.controller.config().clone(), &e.params)?;
        e.track_id = track_id as usize;
        Ok(())
    }

    /// Starts a vehicle's next projections from its rear axle at arc length
    /// `s_rear_m` of its track (see [`Controller::seed_hints`]).
    pub fn seed_vehicle_hints(&mut self, slot: i64, s_rear_m: f64) -> Result<(), FleetError> {
        let i = self.index(slot)?;
        self.slots[i]
            .as_mut()
            .expect("index() checked the slot is in use")
            .controller
            .seed_hints(s_rear_m);
        Ok(())
    }

    /// Forgets a vehicle's projection hints (after a teleport: the next step
    /// searches its whole track).
    pub fn reset_vehicle(&mut self, slot: i64) -> Result<(), FleetError> {
        let i = self.index(slot)?;
        self.slots[i]
            .as_mut()
            .expect("index() checked the slot is in use")
            .controller
            .reset();
        Ok(())
    }

    /// Checks the call (lengths, slots, dt) before anything moves; tells
    /// whether the slots are listed in increasing order.
    fn check(&mut self, inp: &FleetInputs<'_>) -> Result<bool, FleetError> {
        let n = inp.slots.len();
        let cols: [(&'static str, Option<&[f64]>); 12] = [
            ("x", Some(inp.x_m)),
            ("y", Some(inp.y_m)),
            ("theta", Some(inp.theta_rad)),
            ("v", Some(inp.v_mps)),
            ("delta", Some(inp.delta_rad)),
            ("alpha", inp.alpha),
            ("leader_gap", inp.leader_gap_m),
            ("leader_speed", inp.leader_speed_mps),
            ("stop_gap", inp.stop_gap_m),
            ("soft_gap", inp.soft_gap_m),
            ("soft_speed", inp.soft_speed_mps),
            ("speed_limit", inp.speed_limit_mps),
        ];
        for (argument, col) in cols {
            if let Some(c) = col {
                if c.len() != n {
                    return Err(FleetError::Length {
                        argument,
                        expected: n,
                        got: c.len(),
                    });
                }
            }
        }
        if let Some(dt) = inp.dt_s {
            if !(dt.is_finite() && dt > 0.0) {
                return Err(FleetError::Parameter {
                    name: "dt",
                    value: dt,
                    message: "must be finite and > 0",
                });
            }
        }
        self.epoch += 1;
        if self.epoch == FREE {
            // The step numbers start over: no slot in use is listed yet.
            self.marks
                .iter_mut()
                .filter(|m| **m != FREE)
                .for_each(|m| *m = 0);
            self.epoch = 1;
        }
        let mut increasing = true;
        let mut last = -1;
        for &slot in inp.slots {
            increasing &= slot > last;
            last = slot;
            let mark = usize::try_from(slot)
                .ok()
                .and_then(|i| self.marks.get_mut(i))
                .filter(|m| **m != FREE)
                .ok_or(FleetError::UnknownSlot { slot })?;
            if *mark == self.epoch {
                return Err(FleetError::DuplicateSlot { slot });
            }
            *mark = self.epoch;
        }
        Ok(increasing)
    }

    /// Steps the listed vehicles once (see the module docs). Large batches
    /// are split over the available cores (rayon); each vehicle's
    /// result does not depend on the split.
    pub fn step(&mut self, inp: &FleetInputs<'_>) -> Result<FleetOutputs, FleetError> {
        let increasing = self.check(inp)?;
        let n = inp.slots.len();
        // The vehicles in input order (slots are unique: checked). Slots
        // listed in increasing order are found in the registry by each part
        // of a parallel step itself; otherwise the calling thread lists one
        // &mut per slot first, reading every entry (about 30 us for 10,000).
        let mut listed: Vec<&mut Entry>;
        let rows = if increasing {
            Rows::Increasing {
                slots: &mut self.slots,
                first: 0,
            }
        } else {
            let mut by_slot: Vec<Option<&mut Entry>> =
                self.slots.iter_mut().map(Option::as_mut).collect();
            listed = inp
                .slots
                .iter()
                .map(|&s| {
                    by_slot[s as usize]
                        .take()
                        .expect("check() verified every slot once")
                })
                .collect();
            Rows::Listed(&mut listed)
        };
        // Each vehicle's outputs go straight into their columns: a parallel
        // step splits the vehicles and every column at the same index, so
        // each thread writes its own part (no row array to transpose after).
        // The columns are allocated but not filled: each row is written once,
        // by the thread that steps its vehicle (NaN for a failed one), so no
        // thread fills 1.3 MB (10,000 vehicles) before the others can start.
        let mut out = FleetOutputs::unwritten(n, inp.dt_s.is_some());
        let cols = Columns::of(&mut out, n);
        if n < PARALLEL_MIN_VEHICLES || self.threads == 1 {
            step_range(rows, 0, cols, inp, false);
        } else {
            // Each vehicle's row depends on its own entry and the shared
            // inputs only, so any split over threads gives the same rows.
            let work = || step_range(rows, 0, cols, inp, true);
            match &self.pool {
                Some(pool) => pool.install(work),
                None => work(),
            }
        }
        // SAFETY: `step_range` wrote every row of `cols`, the columns' first
        // `n` entries (a panic in it unwinds past this line, the columns
        // still empty).
        unsafe { out.set_written(n) };
        Ok(out)
    }
}

/// Vehicles a parallel step leaves to one thread (at most): a few hundred
/// microseconds of work, so a 10,000-vehicle step splits into a few dozen.
const PARALLEL_GRAIN: usize = 256;

impl FleetOutputs {
    /// Empty columns with room for `n` entries (and the next states' when
    /// `next`), for [`Columns::of`] to write.
    fn unwritten(n: usize, next: bool) -> Self {
        let col = || Vec::with_capacity(n);
        FleetOutputs {
            ok: Vec::with_capacity(n),
            steering_rad: col(),
            accel_mps2: col(),
            alpha: col(),
            lateral_error_m: col(),
            heading_error_rad: col(),
            s_m: col(),
            s_rear_m: col(),
            lateral_error_rear_m: col(),
            lateral_error_front_m: col(),
            curvature_per_m: col(),
            virtual_obstacle_m: col(),
            next: next.then(|| NextStates {
                x_m: col(),
                y_m: col(),
                theta_rad: col(),
                v_mps: col(),
                delta_rad: col(),
            }),
        }
    }

    /// Every column: `ok`, the 11 float outputs, and the 5 next-state
    /// columns with a time step. The one list both [`Columns::of`] (what a
    /// step writes) and [`FleetOutputs::set_written`] (what it then
    /// declares written) take, so the two cannot disagree.
    #[allow(clippy::type_complexity)]
    fn columns_mut(
        &mut self,
    ) -> (
        &mut Vec<bool>,
        [&mut Vec<f64>; 11],
        Option<[&mut Vec<f64>; 5]>,
    ) {
        (
            &mut self.ok,
            [
                &mut self.steering_rad,
                &mut self.accel_mps2,
                &mut self.alpha,
                &mut self.lateral_error_m,
                &mut self.heading_error_rad,
                &mut self.s_m,
                &mut self.s_rear_m,
                &mut self.lateral_error_rear_m,
                &mut self.lateral_error_front_m,
                &mut self.curvature_per_m,
                &mut self.virtual_obstacle_m,
            ],
            self.next.as_mut().map(|nx| {
                [
                    &mut nx.x_m,
                    &mut nx.y_m,
                    &mut nx.theta_rad,
                    &mut nx.v_mps,
                    &mut nx.delta_rad,
                ]
            }),
        )
    }

    /// Sets the length of every column to `n`.
    ///
    /// # Safety
    ///
    /// The first `n` entries of every column (their spare capacity after
    /// [`FleetOutputs::unwritten`]) are written: `Columns::of(self, n)` was
    /// passed whole to [`step_range`] and it returned.
    unsafe fn set_written(&mut self, n: usize) {
        let (ok, f, next) = self.columns_mut();
        ok.set_len(n);
        for c in f.into_iter().chain(next.into_iter().flatten()) {
            c.set_len(n);
        }
    }
}

/// The output columns of the vehicles of one part of a step, not yet
/// written (`next` None without a time step).
struct Columns<'a> {
    ok: &'a mut [MaybeUninit<bool>],
    f: [&'a mut [MaybeUninit<f64>]; 11],
    next: Option<[&'a mut [MaybeUninit<f64>]; 5]>,
}

impl<'a> Columns<'a> {
    /// The first `n` entries of the spare capacity of every column of `out`
    /// (from [`FleetOutputs::unwritten`]).
    fn of(out: &'a mut FleetOutputs, n: usize) -> Self {
        fn spare<T>(c: &mut Vec<T>, n: usize) -> &mut [MaybeUninit<T>] {
            &mut c.spare_capacity_mut()[..n]
        }
        let (ok, f, next) = out.columns_mut();
        Columns {
            ok: spare(ok, n),
            f: f.map(|c| spare(c, n)),
            next: next.map(|cs| cs.map(|c| spare(c, n))),
        }
    }

    /// The first `mid` entries of every column, and the rest.
    fn split_at(self, mid: usize) -> (Self, Self) {
        let (ok_a, ok_b) = self.ok.split_at_mut(mid);
        let split = |c: &'a mut [MaybeUninit<f64>]| c.split_at_mut(mid);
        let [f0, f1, f2, f3, f4, f5, f6, f7, f8, f9, f10] = self.f.map(split);
        let (next_a, next_b) = match self.next.map(|n| n.map(split)) {
            Some([n0, n1, n2, n3, n4]) => (
                Some([n0.0, n1.0, n2.0, n3.0, n4.0]),
                Some([n0.1, n1.1, n2.1, n3.1, n4.1]),
            ),
            None => (None, None),
        };
        (
            Columns {
                ok: ok_a,
                f: [
                    f0.0, f1.0, f2.0, f3.0, f4.0, f5.0, f6.0, f7.0, f8.0, f9.0, f10.0,
                ],
                next: next_a,
            },
            Columns {
                ok: ok_b,
                f: [
                    f0.1, f1.1, f2.1, f3.1, f4.1, f5.1, f6.1, f7.1, f8.1, f9.1, f10.1,
                ],
                next: next_b,
            },
        )
    }

    /// Entry `j` of every column from a vehicle's step: its outputs `o`
    /// and, with a time step, its next state.
    #[inline]
    fn write(&mut self, j: usize, o: &ControlOutput, next: Option<&VehicleState>) {
        self.ok[j].write(true);
        let vals = [
            o.steering_rad,
            o.accel_mps2,
            o.alpha,
            o.lateral_error_m,
            o.heading_error_rad,
            o.s_m,
            o.s_rear_m,
            o.lateral_error_rear_m,
            o.lateral_error_front_m,
            o.curvature_per_m,
            o.virtual_obstacle_m,
        ];
        for (c, v) in self.f.iter_mut().zip(vals) {
            c[j].write(v);
        }
        if let Some(cols) = &mut self.next {
            let n = next.expect("a step with a time step integrates every vehicle it steps");
            let vals = [n.x_m, n.y_m, n.theta_rad, n.v_mps, n.delta_rad];
            for (c, v) in cols.iter_mut().zip(vals) {
                c[j].write(v);
            }
        }
    }

    /// Entry `j` of every column for a vehicle whose step failed: false and
    /// NaN.
    #[cold]
    fn write_failed(&mut self, j: usize) {
        self.ok[j].write(false);
        for c in self.f.iter_mut().chain(self.next.iter_mut().flatten()) {
            c[j].write(f64::NAN);
        }
    }
}

/// The vehicles of the input rows of one part of a step, in row order.
enum Rows<'a, 'e> {
    /// Slots listed in any order: the entry of each row.
    Listed(&'a mut [&'e mut Entry]),
    /// Slots listed in increasing order: the registry from the slot of the
    /// part's first row on, `first` being that slot's number.
    Increasing {
        slots: &'a mut [Option<Entry>],
        first: usize,
    },
}

impl Rows<'_, '_> {
    /// The vehicle of the part's row `j`, listed as `slot`.
    #[inline(always)]
    fn entry(&mut self, j: usize, slot: i64) -> &mut Entry {
        match self {
            Rows::Listed(entries) => entries[j],
            Rows::Increasing { slots, first } => slots[slot as usize - *first]
                .as_mut()
                .expect("check() verified the slot is in use"),
        }
    }

    /// The vehicles of the part's first `mid` rows, and the rest; the rest
    /// begins with input row `at`.
    fn split_at(self, mid: usize, at: usize, inp: &FleetInputs<'_>) -> (Self, Self) {
        match self {
            Rows::Listed(entries) => {
                let (a, b) = entries.split_at_mut(mid);
                (Rows::Listed(a), Rows::Listed(b))
            }
            Rows::Increasing { slots, first } => {
                let (a, b) = slots.split_at_mut(inp.slots[at] as usize - first);
                (
                    Rows::Increasing { slots: a, first },
                    Rows::Increasing {
                        slots: b,
                        first: inp.slots[at] as usize,
                    },
                )
            }
        }
    }
}

/// Steps the vehicles of `rows` (input rows `base..`) into `cols`, writing
/// every row, split in halves over rayon's threads down to
/// [`PARALLEL_GRAIN`] vehicles when `parallel`.
fn step_range(
    mut rows: Rows<'_, '_>,
    base: usize,
    mut cols: Columns<'_>,
    inp: &FleetInputs<'_>,
    parallel: bool,
) {
    let len = cols.ok.len();
    if !parallel || len <= PARALLEL_GRAIN {
        for j in 0..len {
            let e = rows.entry(j, inp.slots[base + j]);
            match step_one(e, inp, base + j) {
                Some((o, next)) => cols.write(j, &o, next.as_ref()),
                None => cols.write_failed(j),
            }
        }
        return;
    }
    let mid = len / 2;
    let (ra, rb) = rows.split_at(mid, base + mid, inp);
    let (ca, cb) = cols.split_at(mid);
    rayon::join(
        || step_range(ra, base, ca, inp, true),
        || step_range(rb, base + mid, cb, inp, true),
    );
}

/// The mark of a slot not in use (see `Fleet::marks`).
const FREE: u32 = u32::MAX;

/// Below this many vehicles a step runs on the calling thread only.
const PARALLEL_MIN_VEHICLES: usize = 1024;
const MAX_THREADS: usize = 8;

/// Steps entry `e` with input row `i`: its outputs and, with a time step,
/// its next state; None for an unusable input (its row stays NaN).
#[inline(always)]
fn step_one(
    e: &mut Entry,
    inp: &FleetInputs<'_>,
    i: usize,
) -> Option<(ControlOutput, Option<VehicleState>)> {
    let opt = |c: Option<&[f64]>| c.map_or(f64::NAN, |c| c[i]);
    let state = VehicleState {
        x_m: inp.x_m[i],
        y_m: inp.y_m[i],
        theta_rad: inp.theta_rad[i],
        v_mps: inp.v_mps[i],
        delta_rad: inp.delta_rad[i],
    };
    let a = opt(inp.alpha);
    let alpha = if a.is_nan() {
        e.controller.config().lat_blend_factor
    } else {
        a
    };
    let mut obstacles = [Obstacle::new(0.0, 0.0); 3];
    let mut n_obs = 0;
    let speed = |v: f64| if v.is_finite() { v.max(0.0) } else { 0.0 };
    let gap = opt(inp.leader_gap_m);
    if gap.is_finite() {
        obstacles[n_obs] = Obstacle::new(gap, speed(opt(inp.leader_speed_mps)))
            .with_reaction(opt(inp.leader_reaction_s));
        n_obs += 1;
    }
    let soft = opt(inp.soft_gap_m);
    if soft.is_finite() {
        obstacles[n_obs] = Obstacle::soft(soft, speed(opt(inp.soft_speed_mps)));
        n_obs += 1;
    }
    let stop = opt(inp.stop_gap_m);
    if stop.is_finite() {
        obstacles[n_obs] = Obstacle::line(stop);
        n_obs += 1;
    }
    let limit = opt(inp.speed_limit_mps);
    let limit = if limit.is_finite() && limit > 0.0 {
        Some(limit)
    } else {
        None
    };
    // The heading's (cos, sin), for the controller and the integration
    // alike (the last step's when it integrated this very heading).
    let h = HeadingTrig::heading_vec(e.next_trig, state.theta_rad);
    let Ok(o) = e
        .controller
        .step_limited_along(&state, h, alpha, &obstacles[..n_obs], limit)
    else {
        return None;
    };
    let next = inp.dt_s.map(|dt| {
        // A vehicle without delay, as Vehicle::step moves it.
        let (next, _, trig) = advance(
            &state,
            &e.params,
            e.controller.config().direction,
            Command {
                steering_rad: o.steering_rad,
                accel_mps2: o.accel_mps2,
            },
            dt,
            || (h.y, h.x),
        );
        e.next_trig = trig;
        next
    });
    Some((o, next))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::{Direction, Vehicle};

    fn fleet_with(n: usize) -> (Fleet, Vec<i64>) {
        let mut f = Fleet::new();
        let a = f
            .add_track(Path::test_track(2.0).unwrap(), ControllerConfig::default())
            .unwrap();
        let b = f
            .add_track(
                Path::circle(40.0, 1e-3).unwrap(),
                ControllerConfig {
                    path_width_m: 6.0,
                    ..Default::default()
                },
            )
            .unwrap();
        let slots = (0..n)
            .map(|i| {
                let t = if i % 2 == 0 { a } else { b } as i64;
                let cfg = (i % 3 == 0).then(|| ControllerConfig {
                    lat_blend_factor: 0.2,
                    ..f.tracks[t as usize].as_ref().unwrap().config.clone()
                });
                f.add_vehicle(t, cfg, None).unwrap() as i64
            })
            .collect();
        (f, slots)
    }

    fn states(n: usize, k: usize) -> Vec<VehicleState> {
        (0..n)
            .map(|i| VehicleState {
                x_m: 1.0 + 0.1 * i as f64 + 0.3 * k as f64,
                y_m: 2.0 - 0.05 * i as f64,
                theta_rad: 0.05 * i as f64,
                v_mps: 3.0,
                delta_rad: 0.01,
            })
            .collect()
    }

    fn cols(s: &[VehicleState]) -> [Vec<f64>; 5] {
        [
            s.iter().map(|s| s.x_m).collect(),
            s.iter().map(|s| s.y_m).collect(),
            s.iter().map(|s| s.theta_rad).collect(),
            s.iter().map(|s| s.v_mps).collect(),
            s.iter().map(|s| s.delta_rad).collect(),
        ]
    }

    #[test]
    fn batch_equals_single_controllers() {
        let n = 7;
        let (mut f, slots) = fleet_with(n);
        // Reference: one Controller per vehicle, stepped one at a time.
        let mut singles: Vec<(Controller, VehicleParams)> = slots
            .iter()
            .map(|&s| {
                let e = f.entry(s).unwrap();
                (
                    Controller::new(
                        e.controller.track().clone(),
                        e.controller.config().clone(),
                        &e.params,
                    )
                    .unwrap(),
                    e.params,
                )
            })
            .collect();
        for k in 0..5 {
            let st = states(n, k);
            let [x, y, th, v, d] = cols(&st);
            let gaps: Vec<f64> = (0..n)
                .map(|i| if i == 2 { 2.0 } else { f64::NAN })
                .collect();
            let lspeed = vec![1.0; n];
            let inp = FleetInputs {
                leader_gap_m: Some(&gaps),
                leader_speed_mps: Some(&lspeed),
                dt_s: Some(0.1),
                ..FleetInputs::new(&slots, &x, &y, &th, &v, &d)
            };
            let out = f.step(&inp).unwrap();
            for i in 0..n {
                let (c, p) = &mut singles[i];
                let obs: Vec<Obstacle> = if i == 2 {
                    vec![Obstacle::new(2.0, 1.0)]
                } else {
                    vec![]
                };
                let o = c.step(&st[i], &obs).unwrap();
                assert!(out.ok[i]);
                assert_eq!(out.steering_rad[i], o.steering_rad);
                assert_eq!(out.accel_mps2[i], o.accel_mps2);
                assert_eq!(out.lateral_error_m[i], o.lateral_error_m);
                assert_eq!(out.s_m[i], o.s_m);
                let mut veh = Vehicle::new(st[i], *p, Direction::Forward, 0);
                veh.step(
                    Command {
                        steering_rad: o.steering_rad,
                        accel_mps2: o.accel_mps2,
                    },
                    0.1,
                );
                let next = out.next.as_ref().unwrap();
                assert_eq!(
                    (next.x_m[i], next.theta_rad[i], next.v_mps[i]),
                    (veh.state.x_m, veh.state.theta_rad, veh.state.v_mps)
                );
            }
            // A slower leader 2 m ahead makes vehicle 2 brake (3 m/s, tau = 1 s).
            assert!(out.accel_mps2[2] < -1.0, "{}", out.accel_mps2[2]);
        }
    }

    #[test]
    fn bad_vehicle_is_flagged_and_others_unaffected() {
        let n = 4;
        let (mut f, slots) = fleet_with(n);
        let (mut g, _) = fleet_with(n);
        let st = states(n, 0);
        let [x, y, mut th, v, d] = cols(&st);
        let [x2, y2, th2, v2, d2] = cols(&st);
        th[1] = f64::NAN;
        let alpha = vec![f64::NAN, 0.5, 2.0, 0.7];
        let out = f
            .step(&FleetInputs {
                alpha: Some(&alpha),
                dt_s: Some(0.05),
                ..FleetInputs::new(&slots, &x, &y, &th, &v, &d)
            })
            .unwrap();
        assert_eq!(out.ok, vec![true, false, false, true]);
        assert!(out.steering_rad[1].is_nan() && out.next.as_ref().unwrap().x_m[2].is_nan());
        // NaN alpha = the configured one (slot 0 was added with 0.2).
        assert_eq!(out.alpha[0], 0.2);
        assert_eq!(out.alpha[3], 0.7);
        let good = [0usize, 3];
        let sl: Vec<i64> = good.iter().map(|&i| slots[i]).collect();
        let pick = |c: &[f64]| good.iter().map(|&i| c[i]).collect::<Vec<f64>>();
        let ref_out = g
            .step(&FleetInputs {
                alpha: Some(&pick(&alpha)),
                dt_s: Some(0.05),
                ..FleetInputs::new(
                    &sl,
                    &pick(&x2),
                    &pick(&y2),
                    &pick(&th2),
                    &pick(&v2),
                    &pick(&d2),
                )
            })
            .unwrap();
        assert_eq!(pick(&out.steering_rad), ref_out.steering_rad);
        assert_eq!(
            pick(&out.next.as_ref().unwrap().y_m),
            ref_out.next.unwrap().y_m
        );
    }

    #[test]
    fn call_errors_name_the_argument_or_slot_and_change_nothing() {
        let (mut f, slots) = fleet_with(3);
        let st = states(3, 0);
        let [x, y, th, v, d] = cols(&st);
        let short = vec![0.0; 2];
        let e = f
            .step(&FleetInputs::new(&slots, &x, &short, &th, &v, &d))
            .unwrap_err();
        assert_eq!(
            e,
            FleetError::Length {
                argument: "y",
                expected: 3,
                got: 2
            }
        );
        assert!(e.to_string().contains("`y`"));
        let e = f
            .step(&FleetInputs {
                stop_gap_m: Some(&short),
                ..FleetInputs::new(&slots, &x, &y, &th, &v, &d)
            })
            .unwrap_err();
        assert!(e.to_string().contains("stop_gap"), "{e}");
        let bad = vec![slots[0], 99, slots[2]];
        assert_eq!(
            f.step(&FleetInputs::new(&bad, &x, &y, &th, &v, &d))
                .unwrap_err(),
            FleetError::UnknownSlot { slot: 99 }
        );
        let neg = vec![slots[0], -1, slots[2]];
        assert!(f
            .step(&FleetInputs::new(&neg, &x, &y, &th, &v, &d))
            .unwrap_err()
            .to_string()
            .contains("slot -1"));
        let dup = vec![slots[0], slots[1], slots[0]];
        assert_eq!(
            f.step(&FleetInputs::new(&dup, &x, &y, &th, &v, &d))
                .unwrap_err(),
            FleetError::DuplicateSlot { slot: slots[0] }
        );
        let e = f
            .step(&FleetInputs {
                dt_s: Some(-0.1),
                ..FleetInputs::new(&slots, &x, &y, &th, &v, &d)
            })
            .unwrap_err();
        assert!(e.to_string().contains("dt"));
        // A rejected call did not advance any controller: the same call on a
        // fresh twin gives the same answer.
        let (mut g, _) = fleet_with(3);
        let a = f
            .step(&FleetInputs::new(&slots, &x, &y, &th, &v, &d))
            .unwrap();
        let b = g
            .step(&FleetInputs::new(&slots, &x, &y, &th, &v, &d))
            .unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn step_numbers_start_over_without_losing_slots() {
        let (mut f, slots) = fleet_with(3);
        f.remove_vehicle(slots[1]).unwrap();
        let live = [slots[0], slots[2]];
        let st = states(2, 0);
        let [x, y, th, v, d] = cols(&st);
        // Two steps before the numbers start over, then the first two.
        f.epoch = FREE - 2;
        for _ in 0..3 {
            f.step(&FleetInputs::new(&live, &x, &y, &th, &v, &d))
                .unwrap();
        }
        assert_eq!(f.epoch, 2);
        let dup = [slots[2], slots[2]];
        assert_eq!(
            f.step(&FleetInputs::new(&dup, &x, &y, &th, &v, &d))
                .unwrap_err(),
            FleetError::DuplicateSlot { slot: slots[2] }
        );
        let gone = [slots[0], slots[1]];
        assert_eq!(
            f.step(&FleetInputs::new(&gone, &x, &y, &th, &v, &d))
                .unwrap_err(),
            FleetError::UnknownSlot { slot: slots[1] }
        );
        assert_eq!(f.add_vehicle(0, None, None).unwrap(), slots[1] as usize);
    }

    #[test]
    fn a_track_is_removed_only_once_nobody_drives_it() {
        let (mut f, slots) = fleet_with(4);
        assert_eq!(f.n_tracks(), 2);
        // Slots 1 and 3 drive track 1.
        assert_eq!(
            f.remove_track(1).unwrap_err(),
            FleetError::TrackInUse {
                track_id: 1,
                slot: 1
            }
        );
        assert_eq!(f.n_tracks(), 2, "a refused removal changes nothing");
        f.set_vehicle_track(slots[1], 0).unwrap();
        f.remove_vehicle(slots[3]).unwrap();
        f.remove_track(1).unwrap();
        assert_eq!(f.n_tracks(), 1);
        for err in [
            f.remove_track(1).unwrap_err(),
            f.add_vehicle(1, None, None).unwrap_err(),
            f.set_vehicle_track(slots[0], 1).unwrap_err(),
        ] {
            assert_eq!(err, FleetError::UnknownTrack { track_id: 1 });
        }
        // The vehicles left still step, and a new track gets the freed id.
        let n = f.len();
        let (x, y, th, v, d) = (
            vec![0.0; n],
            vec![0.5; n],
            vec![0.0; n],
            vec![1.0; n],
            vec![0.0; n],
        );
        let live: Vec<i64> = f.slots().into_iter().map(|s| s as i64).collect();
        f.step(&FleetInputs::new(&live, &x, &y, &th, &v, &d))
            .unwrap();
        let id = f
            .add_track(
                Path::straight(50.0, 1.0).unwrap(),
                ControllerConfig::default(),
            )
            .unwrap();
        assert_eq!(id, 1);
        assert_eq!((f.n_tracks(), f.track_capacity()), (2, 2));
    }

    #[test]
    fn slots_are_reused_and_removed_slots_are_unknown() {
        let (mut f, slots) = fleet_with(4);
        assert_eq!(f.len(), 4);
        f.remove_vehicle(slots[1]).unwrap();
        assert_eq!(
            f.remove_vehicle(slots[1]).unwrap_err(),
            FleetError::UnknownSlot { slot: slots[1] }
        );
        assert_eq!(f.slots(), vec![0, 2, 3]);
        assert_eq!(f.add_vehicle(1, None, None).unwrap(), 1);
        assert_eq!(f.vehicle_track(1).unwrap(), 1);
        assert_eq!(
            f.add_vehicle(5, None, None).unwrap_err(),
            FleetError::UnknownTrack { track_id: 5 }
        );
        let bad = ControllerConfig {
            lat_blend_factor: 1.5,
            ..Default::default()
        };
        assert!(f
            .add_vehicle(0, Some(bad.clone()), None)
            .unwrap_err()
            .to_string()
            .contains("lat_blend_factor"));
        assert!(f.set_vehicle_config(0, bad).is_err());
        f.set_vehicle_config(
            0,
            ControllerConfig {
                lat_blend_factor: 0.9,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(f.vehicle_config(0).unwrap().lat_blend_factor, 0.9);
        assert_eq!(f.len(), 4);
        // A batch large enough to be split over threads equals the serial one.
        let n = 3 * PARALLEL_MIN_VEHICLES / 2;
        let (mut big, big_slots) = fleet_with(n);
        let st = states(n, 1);
        let [x, y, mut th, v, d] = cols(&st);
        // Two unusable rows, in the first part and the last: every thread
        // writes its failed rows too.
        th[5] = f64::NAN;
        th[n - 1] = f64::INFINITY;
        let par = big
            .step(&FleetInputs {
                dt_s: Some(0.1),
                ..FleetInputs::new(&big_slots, &x, &y, &th, &v, &d)
            })
            .unwrap();
        for i in [5, n - 1] {
            assert!(!par.ok[i] && par.steering_rad[i].is_nan());
            assert!(par.next.as_ref().unwrap().x_m[i].is_nan());
        }
        assert_eq!(par.ok.iter().filter(|&&ok| ok).count(), n - 2);
        let (mut small, small_slots) = fleet_with(n);
        for i in (0..n).step_by(97) {
            let one = small
                .step(&FleetInputs {
                    dt_s: Some(0.1),
                    ..FleetInputs::new(
                        &small_slots[i..i + 1],
                        &x[i..i + 1],
                        &y[i..i + 1],
                        &th[i..i + 1],
                        &v[i..i + 1],
                        &d[i..i + 1],
                    )
                })
                .unwrap();
            assert_eq!(par.steering_rad[i], one.steering_rad[0]);
            assert_eq!(
                par.next.as_ref().unwrap().theta_rad[i],
                one.next.as_ref().unwrap().theta_rad[0]
            );
        }
        // Listed in decreasing order, each vehicle gets the same row.
        let (mut rev, rev_slots) = fleet_with(n);
        let back = |c: &[f64]| c.iter().rev().copied().collect::<Vec<f64>>();
        let slots_back: Vec<i64> = rev_slots.iter().rev().copied().collect();
        let out = rev
            .step(&FleetInputs {
                dt_s: Some(0.1),
                ..FleetInputs::new(
                    &slots_back,
                    &back(&x),
                    &back(&y),
                    &back(&th),
                    &back(&v),
                    &back(&d),
                )
            })
            .unwrap();
        let next = out.next.as_ref().unwrap();
        let par_next = par.next.as_ref().unwrap();
        for (a, b) in [
            (&out.steering_rad, &par.steering_rad),
            (&out.accel_mps2, &par.accel_mps2),
            (&out.s_m, &par.s_m),
            (&next.x_m, &par_next.x_m),
            (&next.theta_rad, &par_next.theta_rad),
        ] {
            let bits = |c: Vec<f64>| c.into_iter().map(f64::to_bits).collect::<Vec<u64>>();
            assert_eq!(bits(back(a)), bits(b.clone()));
        }
        assert!(out.ok.iter().rev().eq(par.ok.iter()));
        // A pool of 3 threads and the calling thread alone give the same batch.
        for threads in [3, 1] {
            let (mut g, g_slots) = fleet_with(n);
            g.set_threads(threads);
            let out = g
                .step(&FleetInputs {
                    dt_s: Some(0.1),
                    ..FleetInputs::new(&g_slots, &x, &y, &th, &v, &d)
                })
                .unwrap();
            // (Debug text: NaN entries compare equal there, and every bit counts.)
            assert_eq!(format!("{out:?}"), format!("{par:?}"), "threads {threads}");
        }
        // Empty step is fine.
        let out = f
            .step(&FleetInputs::new(&[], &[], &[], &[], &[], &[]))
            .unwrap();
        assert!(out.ok.is_empty());
    }

    #[test]
    fn speed_limit_caps_the_free_flow_target() {
        let mut fleet = Fleet::new();
        let cfg = ControllerConfig {
            preferred_speed: 10.0,
            ..Default::default()
        };
        let t = fleet
            .add_track(Path::straight(5000.0, 5.0).unwrap(), cfg.clone())
            .unwrap();
        let a = fleet.add_vehicle(t as i64, None, None).unwrap() as i64;
        let b = fleet.add_vehicle(t as i64, None, None).unwrap() as i64;
        let mut st = [(0.0, 0.0, 0.0, 0.0, 0.0); 2];
        st[1].1 = 3.0;
        for _ in 0..1500 {
            let slots = [a, b];
            let cols: Vec<Vec<f64>> = (0..5)
                .map(|k| st.iter().map(|s| [s.0, s.1, s.2, s.3, s.4][k]).collect())
                .collect();
            let limit = [f64::NAN, 5.0];
            let mut inp =
                FleetInputs::new(&slots, &cols[0], &cols[1], &cols[2], &cols[3], &cols[4]);
            inp.speed_limit_mps = Some(&limit);
            inp.dt_s = Some(0.1);
            let out = fleet.step(&inp).unwrap();
            let n = out.next.unwrap();
            for (i, s) in st.iter_mut().enumerate() {
                *s = (
                    n.x_m[i],
                    n.y_m[i],
                    n.theta_rad[i],
                    n.v_mps[i],
                    n.delta_rad[i],
                );
            }
            assert!(
                out.s_rear_m[0] <= out.s_m[0] + 1e-9,
                "the control point is ahead of the rear axle"
            );
        }
        assert!(
            (st[0].3 - 10.0).abs() < 0.2,
            "no limit: preferred speed, got {}",
            st[0].3
        );
        assert!(
            (st[1].3 - 5.0).abs() < 0.1,
            "limited to 5 m/s, got {}",
            st[1].3
        );
    }
}
