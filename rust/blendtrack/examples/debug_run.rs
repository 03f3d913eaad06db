use blendtrack::*;
use std::sync::Arc;
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let alpha: f64 = args[1].parse().unwrap();
    let back = args[2] == "b";
    let circle = args.get(3).map(|s| s == "c").unwrap_or(false);
    let dir = if back { Direction::Backward } else { Direction::Forward };
    let cfg = ControllerConfig { direction: dir, lat_blend_factor: alpha, preferred_speed: if back {1.0} else {3.0}, ..Default::default() };
    let path = if circle { Path::circle(50.0, 1e-3).unwrap() } else { Path::straight(400.0, 1.0).unwrap() };
    let track = Arc::new(Track::new(path, &cfg));
    let tr = simulate(track, &cfg, &VehicleParams::default(), &AlphaSchedule::Constant{alpha}, &SimOptions{duration_s: 120.0, initial_offset_m: 4.0, ..Default::default()}).unwrap();
    for i in (0..tr.len()).step_by(200) {
        println!("t={:6.1} x={:7.2} y={:6.2} th={:6.3} v={:5.2} d={:6.3} e={:6.3} eth={:6.3} dobs={:6.1}", tr.t_s[i], tr.x_m[i], tr.y_m[i], tr.theta_rad[i], tr.v_mps[i], tr.delta_rad[i], tr.lateral_error_m[i], tr.heading_error_rad[i], tr.virtual_obstacle_m[i]);
    }
}
