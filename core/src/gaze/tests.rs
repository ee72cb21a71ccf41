use super::*;
use crate::math::Libm;

fn ray(o: [f64; 3], d: [f64; 3]) -> GazeRay {
    GazeRay {
        origin: Vector3::from(o),
        direction: Vector3::from(d).normalize(),
    }
}

/// A 100 × 60 mm rectangle at depth `z`, centred on (cx, cy), facing the camera.
fn rect(id: &str, cx: f64, cy: f64, z: f64) -> Target {
    Target::new(
        id,
        &[
            [cx - 50.0, cy - 30.0, z],
            [cx + 50.0, cy - 30.0, z],
            [cx + 50.0, cy + 30.0, z],
            [cx - 50.0, cy + 30.0, z],
        ],
    )
    .unwrap()
}

#[test]
fn a_ray_through_a_target_hits_it_at_the_expected_point() {
    let t = [rect("a", 0.0, 0.0, 0.0)];
    // Eyes 400 mm in front of the camera looking back at (10, -5) on the plane z = 0.
    let r = ray([0.0, 0.0, 400.0], [10.0, -5.0, -400.0]);
    let h = locate(&t, &r).unwrap();
    assert_eq!(h.target, Some(0));
    assert_eq!(h.distance_mm, 0.0);
    // u from corner 0 (−50, −30) along +x, v along +y.
    assert!((h.point_mm[0] - 60.0).abs() < 1e-9 && (h.point_mm[1] - 25.0).abs() < 1e-9);
    assert!((t[0].point_at(h.point_mm) - Vector3::new(10.0, -5.0, 0.0)).norm() < 1e-9);
    assert!((h.range_mm - (10f64.powi(2) + 25.0 + 160_000.0).sqrt()).abs() < 1e-9);
}

#[test]
fn the_nearest_of_several_hits_along_the_ray_wins() {
    // A near pane in front of a far one, both on the ray.
    let t = [rect("far", 0.0, 0.0, -500.0), rect("near", 0.0, 0.0, 0.0)];
    let h = locate(&t, &ray([0.0, 0.0, 400.0], [0.0, 0.0, -1.0])).unwrap();
    assert_eq!(h.target, Some(1));
}

#[test]
fn a_miss_names_the_nearest_target_and_its_distance() {
    let t = [
        rect("left", -200.0, 0.0, 0.0),
        rect("right", 200.0, 0.0, 0.0),
    ];
    // Lands at (120, 0): 30 mm from the right pane's left edge (x = 150), 270 from the left's.
    let h = locate(&t, &ray([0.0, 0.0, 400.0], [120.0, 0.0, -400.0])).unwrap();
    assert_eq!((h.target, h.nearest), (None, 1));
    assert!((h.distance_mm - 30.0).abs() < 1e-9, "{}", h.distance_mm);
    // A corner miss measures to the corner: (290, 70) from (250, 30).
    let h = locate(&t, &ray([0.0, 0.0, 400.0], [290.0, 70.0, -400.0])).unwrap();
    assert!(
        (h.distance_mm - 40.0 * 2f64.sqrt()).abs() < 1e-9,
        "{}",
        h.distance_mm
    );
}

#[test]
fn targets_behind_the_eyes_or_parallel_are_never_hit() {
    let t = [rect("behind", 0.0, 0.0, 800.0)];
    let h = locate(&t, &ray([0.0, 0.0, 400.0], [0.0, 0.0, -1.0])).unwrap();
    assert_eq!(h.target, None);
    assert!(h.range_mm.is_infinite());
    // Its centroid is straight behind: as far as from the eyes.
    assert!((h.distance_mm - 400.0).abs() < 1e-9);
    // A ray in the plane's direction never meets it.
    let side = [rect("side", 0.0, 0.0, 0.0)];
    let h = locate(&side, &ray([0.0, 0.0, 400.0], [1.0, 0.0, 0.0])).unwrap();
    assert_eq!(h.target, None);
    assert!((h.distance_mm - 400.0).abs() < 1e-9);
    assert!(locate(&[], &ray([0.0; 3], [0.0, 0.0, 1.0])).is_none());
}

#[test]
fn bad_targets_are_refused() {
    assert!(Target::new("two", &[[0.0; 3], [1.0, 0.0, 0.0]]).is_err());
    assert!(Target::new("line", &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]).is_err());
    assert!(
        Target::new(
            "nan",
            &[[f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        )
        .is_err()
    );
    let bent = [
        [0.0, 0.0, 0.0],
        [100.0, 0.0, 0.0],
        [100.0, 100.0, 10.0],
        [0.0, 100.0, 0.0],
    ];
    assert!(Target::new("bent", &bent).is_err());
    assert!(Target::screen("s", 0.0, 100.0, [0.0, 0.0]).is_err());
    // A non-convex (L-shaped) polygon: the notch is outside.
    let l = Target::new(
        "L",
        &[
            [0.0, 0.0, 0.0],
            [100.0, 0.0, 0.0],
            [100.0, 40.0, 0.0],
            [40.0, 40.0, 0.0],
            [40.0, 100.0, 0.0],
            [0.0, 100.0, 0.0],
        ],
    )
    .unwrap();
    let into = |x: f64, y: f64| {
        locate(
            std::slice::from_ref(&l),
            &ray([x, y, 300.0], [0.0, 0.0, -1.0]),
        )
        .unwrap()
    };
    assert_eq!(into(20.0, 80.0).target, Some(0));
    assert_eq!(into(80.0, 80.0).target, None);
    assert!((into(80.0, 80.0).distance_mm - 40.0).abs() < 1e-9);
}

#[test]
fn a_screen_gives_user_coordinates_from_its_top_left() {
    // A 70 × 150 mm phone screen, the camera 35 mm right of its top-left corner, 8 mm above it.
    let s = Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap();
    let h = locate(
        std::slice::from_ref(&s),
        &ray([0.0, 0.0, 350.0], [0.0, 58.0, -350.0]),
    )
    .unwrap();
    assert_eq!(h.target, Some(0));
    assert!(
        (h.point_mm[0] - 35.0).abs() < 1e-9 && (h.point_mm[1] - 50.0).abs() < 1e-9,
        "{:?}",
        h.point_mm
    );
}

/// Deterministic normal noise (Box–Muller over an xorshift).
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn normal(&mut self) -> f64 {
        let (a, b) = (self.uniform().max(1e-12), self.uniform());
        (-2.0 * a.mln()).sqrt() * (std::f64::consts::TAU * b).mcos()
    }
}

/// A simulated user in front of a phone: per-eye offsets between where the estimate points and
/// where they look (the visual-axis angle and the estimate's bias), gaze noise per frame; each
/// tap is a look at a random screen point. Returns the mean screen error (mm) after each number
/// of taps in `counts`.
fn tap_curve(counts: &[usize], noise_deg: f64, seed: u64) -> Vec<f64> {
    let screen = Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap();
    let eyes = [
        Vector3::new(-31.0, 40.0, 340.0),
        Vector3::new(31.0, 40.0, 340.0),
    ];
    // Estimate = truth rotated by these (yaw, pitch) degrees, per eye: a user whose estimates
    // point about 3° right of and above where they look (their visual axes' angle plus the
    // estimator's bias for their eyes).
    let bias = [[4.0, -3.0], [2.0, -3.5]];
    let mut rng = Noise(seed);
    let look = |rng: &mut Noise, uv: [f64; 2]| -> [GazeRay; 2] {
        let p = screen.point_at(uv);
        [0, 1].map(|e| {
            let truth = (p - eyes[e]).normalize();
            let off = [
                (bias[e][0] + noise_deg * rng.normal()).to_radians(),
                (bias[e][1] + noise_deg * rng.normal()).to_radians(),
            ];
            GazeRay {
                origin: eyes[e],
                direction: rotate_by(&truth, off),
            }
        })
    };
    let mut out = Vec::new();
    // Each count: 10 users' calibrations (different taps), 100 test looks each.
    let (users, trials) = (10, 100);
    for &n in counts {
        let mut err = 0.0;
        for _ in 0..users {
            let mut cal = GazeCalibration::default();
            for _ in 0..n {
                let uv = [70.0 * rng.uniform(), 150.0 * rng.uniform()];
                let rays = look(&mut rng, uv);
                cal.add_tap(&rays, &screen.point_at(uv)).unwrap();
            }
            for _ in 0..trials {
                let uv = [70.0 * rng.uniform(), 150.0 * rng.uniform()];
                let raw = look(&mut rng, uv);
                let d = (cal.correct(0, &raw[0].direction) + cal.correct(1, &raw[1].direction))
                    .normalize();
                let r = GazeRay {
                    origin: (eyes[0] + eyes[1]) / 2.0,
                    direction: d,
                };
                let h = locate(std::slice::from_ref(&screen), &r).unwrap();
                let q = if h.range_mm.is_finite() {
                    h.point_mm
                } else {
                    [f64::INFINITY; 2]
                };
                err += ((q[0] - uv[0]).powi(2) + (q[1] - uv[1]).powi(2)).sqrt();
            }
        }
        out.push(err / f64::from(users * trials));
    }
    out
}

#[test]
fn taps_learn_the_users_offset_and_the_screen_error_falls() {
    let counts = [0, 1, 2, 3, 5, 10, 20];
    let curve = tap_curve(&counts, 2.0, 7);
    eprintln!("screen error (mm) after {counts:?} taps, 2° noise: {curve:.1?}");
    assert!(curve[0] > 25.0, "the simulated bias must matter: {curve:?}");
    assert!(curve[4] < 0.6 * curve[0], "{curve:?}");
    assert!(
        curve[6] < curve[1] && curve[6] < 0.5 * curve[0],
        "{curve:?}"
    );
    // With no noise, one tap recovers the offsets exactly; what is left is geometry: the mean of
    // two eye directions, drawn from the eyes' midpoint, passes the fixated point within a
    // fraction of a millimetre unless both eyes are equally far from it.
    let exact = tap_curve(&[1], 0.0, 3);
    assert!(exact[0] < 0.5, "{exact:?}");
    // Outlier taps (the user looked elsewhere) barely move a median over many.
    let screen = Target::screen("phone", 70.0, 150.0, [35.0, -8.0]).unwrap();
    let mut cal = GazeCalibration::default();
    let eyes = [
        Vector3::new(-31.0, 40.0, 340.0),
        Vector3::new(31.0, 40.0, 340.0),
    ];
    for k in 0..12 {
        let p = screen.point_at([10.0 + 4.0 * f64::from(k), 20.0 + 9.0 * f64::from(k)]);
        let mut rays = [0, 1].map(|e| GazeRay {
            origin: eyes[e],
            direction: rotate_by(&(p - eyes[e]).normalize(), [0.05, -0.03]),
        });
        if k % 4 == 0 {
            rays[0].direction = Vector3::new(0.3, 0.2, -1.0).normalize();
        }
        cal.add_tap(&rays, &p).unwrap();
    }
    let off = cal.offsets_deg();
    assert!((off[1][0] + 0.05f64.to_degrees()).abs() < 1e-6, "{off:?}");
    assert!((off[0][0] + 0.05f64.to_degrees()).abs() < 0.5, "{off:?}");
    cal.reset();
    assert_eq!(cal.taps(), 0);
    assert!(
        cal.add_tap(
            &[ray([0.0; 3], [f64::NAN, 0.0, -1.0]); 2],
            &Vector3::new(0.0, 0.0, -10.0)
        )
        .is_err()
    );
}

#[test]
fn the_filter_smooths_fixations_and_passes_saccades() {
    let f = GazeFilter::default();
    let a = Vector3::new(0.0, 0.0, -1.0);
    let small = rotate_by(&a, [2f64.to_radians(), 0.0]);
    let smoothed = f.apply(Some(&a), &small);
    assert!(smoothed.angle(&a) < small.angle(&a) && smoothed.angle(&a) > 0.0);
    let jump = rotate_by(&a, [20f64.to_radians(), 0.0]);
    assert_eq!(f.apply(Some(&a), &jump), jump);
    assert_eq!(f.apply(None, &small), small);
}

#[test]
fn the_driver_zones_example_is_hit_zone_by_zone() {
    let json = include_str!("../../../examples/driver_zones.json");
    let targets = targets_from_json(json.as_bytes()).unwrap();
    let ids: Vec<&str> = targets.iter().map(|t| t.id.as_str()).collect();
    assert_eq!(
        ids,
        [
            "left_window",
            "left_mirror",
            "road",
            "navigation",
            "rear_mirror",
            "right_mirror",
            "right_window"
        ]
    );
    // The driver's eyes, per the file's description; a look at each zone's centre hits it.
    let eyes = Vector3::new(0.0, 0.0, 600.0);
    for (i, t) in targets.iter().enumerate() {
        let c = t.centroid();
        let h = locate(
            &targets,
            &GazeRay {
                origin: eyes,
                direction: (c - eyes).normalize(),
            },
        )
        .unwrap();
        assert_eq!(h.target, Some(i), "{}", t.id);
    }
}

/// A fitted face at 500 mm, turned by `yaw_deg`.
fn facing(yaw_deg: f64) -> FaceFit {
    FaceFit {
        pose: crate::fit::Pose::from_euler_deg(yaw_deg, 0.0, 0.0, Vector3::new(0.0, 0.0, 500.0)),
        shape: [0.0; crate::model::N_SHAPE],
        animation: [0.0; crate::model::N_ANIM],
        report: crate::fit::FitReport {
            rms_px: 0.0,
            iterations: 0,
            termination: crate::fit::Termination::CostConverged,
            converged: true,
        },
        uncertainty: crate::fit::PoseUncertainty::default(),
    }
}

/// Where the eyes are trusted and where the head direction replaces them: closed eyes, a head
/// turned past the yaw limit, two eyes that disagree.
#[test]
fn the_head_direction_replaces_closed_turned_or_disagreeing_eyes() {
    let cfg = GazeConfig::default();
    let none = GazeCalibration::default();
    let down = [0.1, 0.2, -1.0];
    let eyes =
        |d0: [f64; 3], d1: [f64; 3]| [ray([-30.0, 0.0, 500.0], d0), ray([30.0, 0.0, 500.0], d1)];
    let look = |rays: &[GazeRay; 2], openness: f64, yaw: f64| {
        point_of_gaze_from_rays(rays, openness, &facing(yaw), &none, &cfg, None, &[])
    };
    let open = look(&eyes(down, down), 0.3, 0.0);
    assert_eq!(open.source, GazeSource::Eyes);
    assert!((open.confidence - 1.0).abs() < 1e-9, "{open:?}");
    assert!(open.ray.direction.angle(&Vector3::from(down)) < 1e-9);
    // Closed: confidence 0, the head's direction (towards the camera for a frontal face).
    let closed = look(&eyes(down, down), 0.05, 0.0);
    assert_eq!((closed.source, closed.confidence), (GazeSource::Head, 0.0));
    assert!(closed.ray.direction.angle(&Vector3::new(0.0, 0.0, -1.0)) < 1e-6);
    // Half-closed: half the trust, still the eyes.
    let half = look(&eyes(down, down), 0.14, 0.0);
    assert!((half.confidence - 0.5).abs() < 1e-9 && half.source == GazeSource::Eyes);
    // Turned 50° of the 60° limit: below the 0.25 floor.
    let turned = look(&eyes(down, down), 0.3, 50.0);
    assert_eq!(turned.source, GazeSource::Head);
    assert!((turned.confidence - 1.0 / 6.0).abs() < 1e-9);
    // Eyes 40° apart.
    let apart = look(&eyes([0.35, 0.0, -1.0], [-0.35, 0.0, -1.0]), 0.3, 0.0);
    assert_eq!((apart.source, apart.confidence), (GazeSource::Head, 0.0));
}

/// The eye aspect ratio of drawn eyes: open, closed, and the less open of the two.
#[test]
fn eye_openness_is_the_less_open_eyes_aspect_ratio() {
    // An eye 30 px wide whose lids are `h` px apart at both lid points.
    let draw = |points: &mut [[f32; 2]; 68], first: usize, x0: f32, h: f32| {
        let (y, top, bottom) = (100.0, 100.0 - h / 2.0, 100.0 + h / 2.0);
        let eye = [
            [x0, y],
            [x0 + 10.0, top],
            [x0 + 20.0, top],
            [x0 + 30.0, y],
            [x0 + 20.0, bottom],
            [x0 + 10.0, bottom],
        ];
        points[first..first + 6].copy_from_slice(&eye);
    };
    let mut p = [[0.0f32; 2]; 68];
    draw(&mut p, 36, 100.0, 9.0);
    draw(&mut p, 42, 160.0, 9.0);
    assert!((eye_openness(&p) - 0.3).abs() < 1e-6);
    draw(&mut p, 42, 160.0, 0.0);
    assert_eq!(eye_openness(&p), 0.0);
    assert_eq!(eye_openness(&[[0.0; 2]; 68]), 0.0);
}

/// The head correction (eq. 6.4): off by default (the same rays and direction); with a yaw gain,
/// each eye's eye-in-head yaw moves by K_x (yaw − r_x0); a dominant-eye weight pulls the combined
/// direction towards the eye nearer the camera.
#[test]
fn the_head_correction_shifts_eye_angles_and_weights_the_near_eye() {
    let fit = facing(30.0);
    let (right, left) = ([0.05, 0.0, -1.0], [-0.05, 0.02, -1.0]);
    let raw = [
        ray([-30.0, 0.0, 500.0], right),
        ray([30.0, 0.0, 500.0], left),
    ];
    let off = HeadCorrection::default();
    assert_eq!(off.apply(&raw, &fit), raw);
    let eye_yaw = |d: &Vector3<f64>| {
        let h = fit.pose.rotation.transpose() * d;
        h.x.matan2(-h.z).to_degrees()
    };
    let k = HeadCorrection {
        gain_yaw: -0.5,
        ref_yaw_deg: 10.0,
        ..off
    };
    let moved = k.apply(&raw, &fit);
    for e in 0..2 {
        let shift = eye_yaw(&moved[e].direction) - eye_yaw(&raw[e].direction);
        assert!((shift + 10.0).abs() < 1e-9, "eye {e}: {shift}");
        assert!((moved[e].direction.norm() - 1.0).abs() < 1e-12);
    }
    // Equal weights by default; a dominant eye leans the combined direction its way.
    let look = |config: &GazeConfig| {
        point_of_gaze_from_rays(
            &raw,
            0.3,
            &fit,
            &GazeCalibration::default(),
            config,
            None,
            &[],
        )
    };
    let plain = look(&GazeConfig::default());
    let mean = (raw[0].direction + raw[1].direction).normalize();
    assert_eq!(plain.ray.direction, mean);
    let dominant = look(&GazeConfig {
        head_correction: HeadCorrection {
            dominant_weight: 1.0,
            ..off
        },
        ..GazeConfig::default()
    });
    let near = if (fit.pose.rotation * Vector3::new(1.0, 0.0, 0.0)).z < 0.0 {
        1
    } else {
        0
    };
    let to = |g: &PointOfGaze, e: usize| g.ray.direction.angle(&raw[e].direction);
    assert!(to(&dominant, near) < to(&plain, near), "{dominant:?}");
}

/// An independent check of one target against a ray: where the ray meets the plane through the
/// target's first three corners in front of the eyes, and how far inside the polygon (a convex
/// one, either winding) that point lies (negative outside).
fn meet_convex(t: &Target, r: &GazeRay) -> Option<(f64, Vector3<f64>, f64)> {
    let c = t.corners();
    let n = (c[1] - c[0]).cross(&(c[2] - c[0])).normalize();
    let denom = n.dot(&r.direction);
    if denom.abs() < 1e-9 {
        return None;
    }
    let s = n.dot(&(c[0] - r.origin)) / denom;
    if s <= 0.0 {
        return None;
    }
    let p = r.origin + r.direction * s;
    let margin = (0..c.len())
        .map(|i| {
            let e = c[(i + 1) % c.len()] - c[i];
            e.cross(&(p - c[i])).dot(&n) / e.norm()
        })
        .fold(f64::INFINITY, f64::min);
    Some((s, p, margin))
}

/// What apps draw is the point of gaze's ray and its target together, so the target must be where
/// that very ray lands — whichever direction it took (the eyes' mean, the head's direction where
/// the eyes are not trusted, calibrated, filtered) and not where either eye's own ray, or the
/// eyes' mean when the head stood in, would land.
#[test]
fn the_reported_target_is_where_the_reported_ray_lands() {
    let mut rng = Noise(0x9e37_79b9_7f4a_7c15);
    let mut previous: Option<Vector3<f64>> = None;
    let (mut hits, mut misses, mut heads, mut split, mut head_moved) = (0, 0, 0, 0, 0);
    for k in 0..4000 {
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
        // Targets: convex polygons (points on an ellipse at increasing angles) in random planes
        // round the camera, either winding.
        let mut targets = Vec::new();
        for i in 0..1 + k % 4 {
            let centre = Vector3::new(u(-250.0, 250.0), u(-250.0, 250.0), u(-300.0, 250.0));
            let normal = Vector3::new(u(-0.6, 0.6), u(-0.6, 0.6), 1.0).normalize();
            let a = normal.cross(&Vector3::new(0.3, 1.0, 0.1)).normalize();
            let b = normal.cross(&a);
            let (ra, rb, spin) = (u(20.0, 150.0), u(20.0, 150.0), u(0.0, 6.3));
            let sides = 3 + (k / 4) % 5;
            let mut corners: Vec<[f64; 3]> = (0..sides)
                .map(|j| {
                    let t = spin + std::f64::consts::TAU * j as f64 / sides as f64;
                    (centre + a * (ra * t.mcos()) + b * (rb * t.msin())).into()
                })
                .collect();
            if k % 3 == 0 {
                corners.reverse();
            }
            targets.push(Target::new(format!("t{i}"), &corners).unwrap());
        }
        let mid = Vector3::new(u(-100.0, 100.0), u(-80.0, 80.0), u(350.0, 700.0));
        let (yaw, openness) = (u(-65.0, 65.0), u(0.05, 0.35));
        let mut raw = [-1.0, 1.0].map(|side| {
            let aim = targets[0].centroid() + Vector3::new(u(-120.0, 120.0), u(-120.0, 120.0), 0.0);
            let spread = if k % 7 == 0 { 20.0 } else { 3.0 };
            ray(
                (mid + Vector3::new(side * 31.0, 0.0, 0.0)).into(),
                (rotate_by(
                    &(aim - mid).normalize(),
                    [
                        u(-spread, spread).to_radians(),
                        u(-spread, spread).to_radians(),
                    ],
                ))
                .into(),
            )
        });
        let mut open = openness;
        let mut face_yaw = yaw;
        if k % 10 == 0 {
            // Each eye on its own pane, the panes apart: either eye's ray hits, their mean lands
            // in the gap between.
            let z = u(-100.0, 100.0);
            targets = vec![rect("left", -60.0, 0.0, z), rect("right", 60.0, 0.0, z)];
            for (e, x) in [(0, -60.0), (1, 60.0)] {
                raw[e] = ray(
                    [x / 2.0, 0.0, mid.z],
                    (Vector3::new(x, 0.0, z) - Vector3::new(x / 2.0, 0.0, mid.z)).into(),
                );
            }
            (open, face_yaw) = (0.3, 0.0);
        }
        let mut calibration = GazeCalibration::default();
        for _ in 0..k % 3 {
            let p = Vector3::new(u(-50.0, 50.0), u(-50.0, 50.0), 0.0);
            calibration.add_tap(&raw, &p).unwrap();
        }
        let config = GazeConfig {
            filter: (k % 5 == 2).then(GazeFilter::default),
            ..GazeConfig::default()
        };
        let fit = facing(face_yaw);
        let g = point_of_gaze_from_rays(
            &raw,
            open,
            &fit,
            &calibration,
            &config,
            previous.as_ref(),
            &targets,
        );
        previous = Some(g.ray.direction);
        let h = g.hit.unwrap();
        let meets: Vec<_> = targets.iter().map(|t| meet_convex(t, &g.ray)).collect();
        let reported = h.target.unwrap_or(h.nearest);
        let t = &targets[reported];
        match meets[reported] {
            Some((s, p, _)) => {
                let err = (t.point_at(h.point_mm) - p).norm();
                assert!(
                    err < 1e-6,
                    "case {k}: point {:?} is {err} mm off the ray",
                    h.point_mm
                );
                assert!((h.range_mm - s).abs() < 1e-6, "case {k}");
            }
            None => {
                assert_eq!(h.target, None, "case {k}: hit a plane the ray never meets");
                assert!(h.range_mm.is_infinite(), "case {k}");
            }
        }
        // Hit exactly when the ray's point lies inside a polygon, and then the nearest such
        // along the ray; points within rounding of an edge may go either way.
        if meets.iter().flatten().any(|m| m.2.abs() < 1e-6) {
            continue;
        }
        let inside = meets
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.filter(|m| m.2 > 0.0).map(|m| (i, m.0)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i);
        assert_eq!(h.target, inside, "case {k}: {h:?}");
        assert_eq!(h.distance_mm == 0.0, inside.is_some(), "case {k}: {h:?}");
        if inside.is_some() {
            hits += 1;
        } else {
            misses += 1;
        }
        let eyes_mean = GazeRay {
            origin: g.ray.origin,
            direction: (g.eyes[0].direction + g.eyes[1].direction).normalize(),
        };
        if g.source == GazeSource::Head {
            heads += 1;
            if locate(&targets, &eyes_mean).map(|e| (e.target, e.nearest))
                != Some((h.target, h.nearest))
            {
                head_moved += 1;
            }
        }
        if k % 10 == 0 {
            assert_eq!(g.source, GazeSource::Eyes, "case {k}");
            if calibration.taps() == 0 {
                for e in &g.eyes {
                    assert!(locate(&targets, e).unwrap().target.is_some(), "case {k}");
                }
                assert_eq!(h.target, None, "case {k}: the eyes' mean lands between");
                split += 1;
            }
        }
    }
    // Every kind of case above was met.
    let counts = (hits, misses, heads, split, head_moved);
    assert!(hits > 200 && misses > 200 && heads > 200, "{counts:?}");
    assert!(split > 50 && head_moved > 50, "{counts:?}");
}
