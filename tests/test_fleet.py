"""Fleet: the batch step equals single-vehicle steps; errors name their cause."""

from __future__ import annotations

import numpy as np
import pytest

import blendtrack

N = 12


def _states(path: blendtrack.Path, n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    s = rng.uniform(0.0, path.length_m, n)
    pts = np.array([path.point_at(float(x)) for x in s])
    heading = np.array([path.heading_at(float(x)) for x in s])
    return {
        "x": pts[:, 0] + rng.uniform(-1, 1, n),
        "y": pts[:, 1] + rng.uniform(-1, 1, n),
        "theta": heading + rng.uniform(-0.1, 0.1, n),
        "v": rng.uniform(0.5, 5.0, n),
        "delta": rng.uniform(-0.1, 0.1, n),
    }


def _fleet(tracks: list[blendtrack.Path], n: int) -> tuple[blendtrack.Fleet, list[int]]:
    fleet = blendtrack.Fleet()
    ids = [fleet.add_track(p, blendtrack.ControllerConfig(path_width_m=8.0)) for p in tracks]
    slots = []
    for i in range(n):
        cfg = blendtrack.ControllerConfig(path_width_m=8.0, lat_blend_factor=(i % 5) / 4)
        slots.append(fleet.add_vehicle(ids[i % len(ids)], cfg))
    return fleet, slots


def test_batch_equals_n_single_vehicle_steps() -> None:
    path = blendtrack.Path.test_track(1.0)
    fleet, slots = _fleet([path], N)
    # N single-vehicle fleets, each with the same track and config.
    singles = []
    for i in range(N):
        f = blendtrack.Fleet()
        t = f.add_track(path, blendtrack.ControllerConfig(path_width_m=8.0))
        singles.append((f, f.add_vehicle(t, fleet.vehicle_config(slots[i]))))
    st = _states(path, N, 0)
    gaps = np.where(np.arange(N) % 3 == 0, 5.0, np.nan)
    for _ in range(5):
        out = fleet.step(np.array(slots), **st, leader_gap=gaps, leader_speed=np.ones(N), dt=0.05)
        assert out["ok"].all()
        for i, (f, s) in enumerate(singles):
            one = f.step([s], *[st[k][i : i + 1] for k in ("x", "y", "theta", "v", "delta")], leader_gap=gaps[i : i + 1], leader_speed=[1.0], dt=0.05)
            for key in ("steering_rad", "accel_mps2", "lateral_error_m", "heading_error_rad", "s_m", "x_m", "v_mps", "delta_rad"):
                assert out[key][i] == one[key][0], (key, i)
        st = {"x": out["x_m"], "y": out["y_m"], "theta": out["theta_rad"], "v": out["v_mps"], "delta": out["delta_rad"]}
    # Per-vehicle alpha: the configured one unless the step overrides it.
    np.testing.assert_array_equal(out["alpha"], [(i % 5) / 4 for i in range(N)])


def test_vehicles_on_different_tracks_and_dynamic_slots() -> None:
    fleet, slots = _fleet([blendtrack.Path.test_track(1.0), blendtrack.Path.circle(30.0)], 4)
    assert fleet.n_tracks == 2 and len(fleet) == 4
    assert [fleet.vehicle_track(s) for s in slots] == [0, 1, 0, 1]
    fleet.remove_vehicle(slots[1])
    np.testing.assert_array_equal(fleet.slots(), [slots[0], slots[2], slots[3]])
    with pytest.raises(blendtrack.InputError, match=f"slot {slots[1]}"):
        fleet.step([slots[1]], [0.0], [0.0], [0.0], [1.0], [0.0])
    assert fleet.add_vehicle(1) == slots[1]  # the freed slot is reused
    with pytest.raises(blendtrack.InputError, match="track id 7"):
        fleet.add_vehicle(7)
    fleet.set_vehicle_config(slots[0], blendtrack.ControllerConfig(lat_blend_factor=0.9))
    assert fleet.vehicle_config(slots[0]).lat_blend_factor == 0.9


def test_call_errors_name_the_argument() -> None:
    path = blendtrack.Path.test_track(1.0)
    fleet, slots = _fleet([path], 3)
    st = _states(path, 3, 1)
    with pytest.raises(blendtrack.InputError, match="`theta`") as info:
        fleet.step(slots, st["x"], st["y"], st["theta"][:2], st["v"], st["delta"])
    assert isinstance(info.value, ValueError)
    with pytest.raises(blendtrack.InputError, match="leader_speed"):
        fleet.step(slots, **st, leader_speed=np.ones(4))
    with pytest.raises(blendtrack.InputError, match="more than once"):
        fleet.step([slots[0], slots[0], slots[1]], **st)
    with pytest.raises(blendtrack.InputError, match="dt"):
        fleet.step(slots, **st, dt=-0.1)
    with pytest.raises(blendtrack.ConfigError, match="lat_blend_factor"):
        bad = blendtrack.ControllerConfig()
        bad.lat_blend_factor = 2.0
        fleet.add_vehicle(0, bad)


def test_one_bad_vehicle_does_not_spoil_the_others() -> None:
    path = blendtrack.Path.test_track(1.0)
    fleet, slots = _fleet([path], 4)
    twin, _ = _fleet([path], 4)
    st = _states(path, 4, 2)
    bad = {k: v.copy() for k, v in st.items()}
    bad["x"][1] = np.nan
    alpha = np.array([np.nan, 0.5, 1.5, 0.3])
    out = fleet.step(slots, **bad, alpha=alpha, dt=0.1)
    np.testing.assert_array_equal(out["ok"], [True, False, False, True])
    assert np.isnan(out["steering_rad"][1]) and np.isnan(out["x_m"][2])
    ref = twin.step([slots[0], slots[3]], *[st[k][[0, 3]] for k in ("x", "y", "theta", "v", "delta")], alpha=alpha[[0, 3]], dt=0.1)
    np.testing.assert_array_equal(out["steering_rad"][[0, 3]], ref["steering_rad"])
    np.testing.assert_array_equal(out["y_m"][[0, 3]], ref["y_m"])


def test_inputs_of_other_dtypes_are_accepted() -> None:
    path = blendtrack.Path.straight(200.0)
    fleet = blendtrack.Fleet()
    t = fleet.add_track(path)
    s = fleet.add_vehicle(t)
    out = fleet.step(np.array([s], dtype=np.int32), [10], [1], np.array([0.0], dtype=np.float32), [2.0], [0.0])
    assert out["ok"][0] and out["lateral_error_m"][0] == pytest.approx(1.0)
    assert "x_m" not in out  # no dt, no next state


def test_axle_errors_of_a_yawed_vehicle_on_a_straight() -> None:
    """On the centreline of a straight, yawed by 0.1 rad: the rear axle's
    error is 0, the front axle's E sin(0.1) (E = 2.6 m, to the left: > 0),
    the control point's alpha times that."""
    fleet = blendtrack.Fleet()
    track = fleet.add_track(blendtrack.Path.straight(200.0, 1.0), blendtrack.ControllerConfig())
    alpha = 0.3
    slot = fleet.add_vehicle(track, blendtrack.ControllerConfig(lat_blend_factor=alpha))
    one = np.array
    out = fleet.step(one([slot]), one([50.0]), one([0.0]), one([0.1]), one([5.0]), one([0.0]))
    front = 2.6 * np.sin(0.1)
    assert out["lateral_error_rear_m"][0] == pytest.approx(0.0, abs=1e-12)
    assert out["lateral_error_front_m"][0] == pytest.approx(front, rel=1e-12)
    assert out["lateral_error_m"][0] == pytest.approx(alpha * front, rel=1e-12)


def test_soft_gap_is_braked_for_at_max_deceleration_at_most() -> None:
    """Fleet.step's soft obstacle (a vehicle to line up behind): the same
    standing vehicle 3 m ahead at 15 m/s is an emergency as a leader and a
    b_f stop as a soft gap; where the law asks for less the two agree; a
    soft column of the wrong length is refused by name."""
    path = blendtrack.Path(np.column_stack([np.arange(0.0, 200.0), np.zeros(200)]))
    fleet = blendtrack.Fleet()
    cfg = blendtrack.ControllerConfig(preferred_speed=15.0)
    slot = fleet.add_vehicle(fleet.add_track(path, cfg), cfg)

    def accel(**obstacle: list[float]) -> float:
        out = fleet.step([slot], [20.0], [0.0], [0.0], [15.0], [0.0], **obstacle)
        return float(out["accel_mps2"][0])

    assert accel(leader_gap=[3.0], leader_speed=[0.0]) < cfg.max_deceleration - 1.0
    assert accel(soft_gap=[3.0], soft_speed=[0.0]) == cfg.max_deceleration
    assert accel(soft_gap=[35.0], soft_speed=[0.0]) == accel(leader_gap=[35.0], leader_speed=[0.0]) > cfg.max_deceleration
    with pytest.raises(blendtrack.InputError, match="soft_gap"):
        accel(soft_gap=[3.0, 4.0])
