//! Round trips, hand computations, validity limits and parameter checks of all models.

use super::fisheye::deriv_coeffs_fisheye;
use super::poly::{first_positive_root, monotone_on, poly_eval};
use super::radtan::deriv_coeffs_radtan;
use super::*;
use approx::assert_relative_eq;
use nalgebra::{Vector2, Vector3};
use proptest::prelude::*;
use std::f64::consts::PI;

fn radtan_cam() -> CameraModel {
    CameraModel {
        width: 1280,
        height: 960,
        fx: 700.0,
        fy: 702.5,
        cx: 645.3,
        cy: 478.9,
        skew: 0.8,
        distortion: Distortion::RadTan {
            k1: -0.28,
            k2: 0.07,
            p1: 1e-4,
            p2: -2e-4,
            k3: 0.0,
        },
    }
}

const FK: [f64; 4] = [0.05, -0.01, 0.002, -0.0005];

fn fisheye_cam(hfov: f64) -> CameraModel {
    let mut c = CameraModel::fisheye_hfov(1280, 960, hfov, FK).expect("valid fisheye");
    c.cx += 3.7;
    c.cy -= 2.1;
    c.fy *= 1.002;
    c.skew = -0.4;
    c
}

fn pinhole_cam() -> CameraModel {
    CameraModel {
        skew: -0.6974,
        ..CameraModel::pinhole(800, 600, 573.8534, 575.0448, 406.0101, 309.0112)
    }
}

fn assert_pixel_round_trip(cam: &CameraModel, u: f64, v: f64) {
    let px = Vector2::new(u, v);
    let ray = cam
        .unproject(&px)
        .unwrap_or_else(|| panic!("unproject failed at {px:?}"));
    assert_relative_eq!(ray.norm(), 1.0, epsilon = 1e-12);
    let back = cam
        .project(&ray)
        .unwrap_or_else(|| panic!("project failed for {ray:?}"));
    assert!((back - px).norm() < 1e-7, "{px:?} -> {ray:?} -> {back:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn pinhole_pixel_round_trip(u in -0.5f64..799.5, v in -0.5f64..599.5) {
        assert_pixel_round_trip(&pinhole_cam(), u, v);
    }

    #[test]
    fn radtan_pixel_round_trip(u in -0.5f64..1279.5, v in -0.5f64..959.5) {
        assert_pixel_round_trip(&radtan_cam(), u, v);
    }

    #[test]
    fn fisheye_pixel_round_trip(u in -0.5f64..1279.5, v in -0.5f64..959.5) {
        assert_pixel_round_trip(&fisheye_cam(160.0), u, v);
    }

    #[test]
    fn ray_round_trip(
        az in -PI..PI,
        el_frac in 0.0f64..0.999,
        scale in 1e-3f64..1e3,
        which in 0usize..4,
    ) {
        let (cam, max_angle) = match which {
            0 => (pinhole_cam(), 1.4),
            1 => (radtan_cam(), 1.2),
            2 => (fisheye_cam(160.0), fisheye_cam(160.0).max_ray_angle()),
            _ => (fisheye_cam(220.0), fisheye_cam(220.0).max_ray_angle()),
        };
        let theta = el_frac * max_angle;
        let ray = Vector3::new(theta.sin() * az.cos(), theta.sin() * az.sin(), theta.cos());
        let px = cam.project(&(ray * scale)).expect("ray inside the valid domain");
        let back = cam.unproject(&px).expect("pixel inside the invertible domain");
        prop_assert!((back - ray).norm() < 1e-9, "{:?} -> {:?} -> {:?}", ray, px, back);
    }

    #[test]
    fn rescale_law(
        x in -0.8f64..0.8, y in -0.6f64..0.6,
        w in 100usize..4000, h in 100usize..3000, which in 0usize..3,
    ) {
        let cam = match which { 0 => pinhole_cam(), 1 => radtan_cam(), _ => fisheye_cam(160.0) };
        let (sx, sy) = (w as f64 / cam.width as f64, h as f64 / cam.height as f64);
        let ray = Vector3::new(x, y, 1.0);
        let p = cam.project(&ray).expect("valid ray");
        let q = cam.rescaled(w, h).project(&ray).expect("valid ray");
        prop_assert!((q.x - ((p.x + 0.5) * sx - 0.5)).abs() < 1e-8);
        prop_assert!((q.y - ((p.y + 0.5) * sy - 0.5)).abs() < 1e-8);
    }

    #[test]
    fn monotone_check_matches_sampling(
        k in prop::array::uniform4(-1.0f64..1.0),
        cubic in any::<bool>(),
        t in 0.0f64..10.0,
    ) {
        let c = if cubic {
            deriv_coeffs_radtan(k[0], k[1], k[2])
        } else {
            deriv_coeffs_fisheye(&k)
        };
        let min = (0..=4000).map(|i| poly_eval(&c, t * i as f64 / 4000.0)).fold(f64::INFINITY, f64::min);
        let got = monotone_on(&c, t);
        if min > 1e-9 {
            prop_assert!(got, "{:?} t={} min={}", c, t, min);
        } else if min < -1e-9 {
            prop_assert!(!got, "{:?} t={} min={}", c, t, min);
        }
        // The limit functions agree with the check.
        let lim = first_positive_root(&c, f64::INFINITY).unwrap_or(f64::INFINITY);
        if t < lim * (1.0 - 1e-9) {
            prop_assert!(monotone_on(&c, t));
        } else if t > lim * (1.0 + 1e-9) {
            prop_assert!(!monotone_on(&c, t));
        }
    }
}

#[test]
fn radtan_matches_hand_computation() {
    let cam = CameraModel {
        width: 1000,
        height: 800,
        fx: 500.0,
        fy: 510.0,
        cx: 499.5,
        cy: 399.5,
        skew: 0.0,
        distortion: Distortion::RadTan {
            k1: -0.28,
            k2: 0.07,
            p1: 1e-4,
            p2: -2e-4,
            k3: 0.01,
        },
    };
    // Ray (0.6, -0.4, 2): x = 0.3, y = -0.2, r^2 = 0.13,
    // radial = 1 - 0.28*0.13 + 0.07*0.0169 + 0.01*0.002197 = 0.96480497
    // xd = 0.3*radial + 2*p1*x*y + p2*(r^2 + 2x^2) = 0.28944149 - 0.000012 - 0.000062 = 0.289367491
    // yd = -0.2*radial + p1*(r^2 + 2y^2) + 2*p2*x*y = -0.19296099 + 0.000021 + 0.000024 = -0.192915994
    // u = 500*xd + 499.5 = 644.1837455, v = 510*yd + 399.5 = 301.112843
    let p = cam.project(&Vector3::new(0.6, -0.4, 2.0)).expect("valid");
    assert_relative_eq!(p.x, 644.1837455, epsilon = 1e-6);
    assert_relative_eq!(p.y, 301.1128431, epsilon = 1e-6);
}

#[test]
fn fisheye_matches_hand_computation() {
    let cam = CameraModel {
        width: 1000,
        height: 800,
        fx: 400.0,
        fy: 401.0,
        cx: 500.0,
        cy: 400.0,
        skew: 2.0,
        distortion: Distortion::Fisheye {
            k1: FK[0],
            k2: FK[1],
            k3: FK[2],
            k4: FK[3],
        },
    };
    // Ray (3, 4, 5): sqrt(X^2+Y^2) = 5, theta = pi/4, t = theta^2 = 0.6168503,
    // theta_d = theta (1 + 0.05 t - 0.01 t^2 + 0.002 t^3 - 0.0005 t^4) = 0.80694518
    // xd = 0.6 theta_d, yd = 0.8 theta_d
    // u = 400 xd + 2 yd + 500 = 694.957954, v = 401 yd + 400 = 658.868012
    let p = cam.project(&Vector3::new(3.0, 4.0, 5.0)).expect("valid");
    assert_relative_eq!(p.x, 694.9579544, epsilon = 1e-6);
    assert_relative_eq!(p.y, 658.8680123, epsilon = 1e-6);
    // A ray behind the image plane (theta = atan2(1, -0.4) = 111.8 deg) is valid here.
    let th = 1.0f64.atan2(-0.4);
    let t = th * th;
    let td = th * (1.0 + 0.05 * t - 0.01 * t * t + 0.002 * t * t * t - 0.0005 * t * t * t * t);
    let back = cam
        .project(&Vector3::new(1.0, 0.0, -0.4))
        .expect("theta < limit");
    assert_relative_eq!(back.x, 400.0 * td + 500.0, epsilon = 1e-9);
    assert_relative_eq!(back.y, 400.0, epsilon = 1e-12);
    // 135 degrees is beyond this polynomial's monotone range.
    assert!(cam.project(&Vector3::new(1.0, 0.0, -1.0)).is_none());
}

#[test]
fn validity_limits() {
    // k1 = -0.28 only: d/dr r(1 + k1 r^2) = 1 - 0.84 r^2 = 0 at r^2 = 1/0.84.
    let cam = CameraModel {
        distortion: Distortion::RadTan {
            k1: -0.28,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0,
        },
        ..pinhole_cam()
    };
    let r_max = (1.0f64 / 0.84).sqrt();
    assert_relative_eq!(cam.max_ray_angle(), r_max.atan(), epsilon = 1e-12);
    assert!(cam
        .project(&Vector3::new(r_max * 0.999, 0.0, 1.0))
        .is_some());
    assert!(cam
        .project(&Vector3::new(r_max * 1.001, 0.0, 1.0))
        .is_none());
    // Pixel beyond the maximum distorted radius is not invertible.
    let rd_max = r_max * (1.0 - 0.28 * r_max * r_max);
    let inside = Vector2::new(cam.cx + cam.fx * rd_max * 0.99, cam.cy);
    let outside = Vector2::new(cam.cx + cam.fx * rd_max * 1.01, cam.cy);
    assert!(cam.unproject(&inside).is_some());
    assert!(cam.unproject(&outside).is_none());
    // Realistic radtan: monotone everywhere (1 - 0.84 s + 0.35 s^2 > 0).
    assert_eq!(radtan_cam().max_ray_angle(), PI / 2.0);
    // Pinhole / radtan reject rays at or behind 90 degrees.
    for cam in [pinhole_cam(), radtan_cam()] {
        assert!(cam.project(&Vector3::new(1.0, 0.0, 0.0)).is_none());
        assert!(cam.project(&Vector3::new(0.0, 1.0, -0.5)).is_none());
        assert!(cam.project(&Vector3::zeros()).is_none());
        assert!(cam.project(&Vector3::new(f64::NAN, 0.0, 1.0)).is_none());
    }
    // Fisheye: limit is the first root of 1 + 0.15 t - 0.05 t^2 + 0.014 t^3 - 0.0045 t^4.
    let f = fisheye_cam(160.0);
    let lim = f.max_ray_angle();
    let d = |th: f64| {
        let t = th * th;
        1.0 + 0.15 * t - 0.05 * t * t + 0.014 * t * t * t - 0.0045 * t * t * t * t
    };
    assert!(d(lim).abs() < 1e-9, "derivative at limit {}", d(lim));
    assert!(lim > 2.0 && lim < PI);
    let ray = |th: f64| Vector3::new(th.sin(), 0.0, th.cos());
    assert!(f.project(&ray(lim - 1e-6)).is_some());
    assert!(f.project(&ray(lim + 1e-6)).is_none());
    assert!(f.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    assert!(f.project(&Vector3::new(0.0, 0.0, 1.0)).is_some());
    // Equidistant fisheye (all k zero) is valid up to (not including) pi.
    let eq = CameraModel::fisheye_hfov(1000, 1000, 350.0, [0.0; 4]).expect("valid");
    assert_eq!(eq.max_ray_angle(), PI);
    assert_relative_eq!(eq.hfov_deg(), 350.0, epsilon = 1e-9);
}

#[test]
fn strong_distortion_inverts() {
    // Strong barrel with a k3 term: fixed-point iteration would diverge near the edge.
    let cam = CameraModel {
        distortion: Distortion::RadTan {
            k1: -0.45,
            k2: 0.25,
            p1: 1e-3,
            p2: -1e-3,
            k3: -0.06,
        },
        ..radtan_cam()
    };
    let lim = cam.max_ray_angle();
    for i in 0..200 {
        let th = lim * (i as f64 + 0.5) / 200.0 * 0.999;
        for az in [0.0, 0.7, 2.0, -2.5] {
            let ray = Vector3::new(th.sin() * f64::cos(az), th.sin() * f64::sin(az), th.cos());
            let px = cam.project(&ray).expect("valid");
            let back = cam.unproject(&px).expect("invertible");
            assert!(
                (back - ray).norm() < 1e-8,
                "theta {th}: {ray:?} -> {back:?}"
            );
        }
    }
}

#[test]
fn hfov_of_constructors() {
    for hfov in [1.0, 30.0, 90.0, 120.0, 179.0] {
        let cam = CameraModel::pinhole_hfov(1920, 1080, hfov).expect("valid");
        assert_relative_eq!(cam.hfov_deg(), hfov, epsilon = 1e-9);
        assert_relative_eq!(cam.cx, 959.5);
        assert_relative_eq!(cam.cy, 539.5);
    }
    for hfov in [60.0, 150.0, 190.0, 220.0] {
        let cam = CameraModel::fisheye_hfov(1280, 960, hfov, FK).expect("valid");
        assert_relative_eq!(cam.hfov_deg(), hfov, epsilon = 1e-9);
    }
    // Distorted lens: barrel distortion widens the field of view versus the pinhole.
    let r = radtan_cam();
    let pin = CameraModel {
        distortion: Distortion::None,
        ..r.clone()
    };
    assert!(r.hfov_deg() > pin.hfov_deg() + 5.0);
}

#[test]
fn invalid_values_rejected() {
    use CameraError::Invalid;
    let name = |r: Result<CameraModel, CameraError>| match r {
        Err(Invalid { name, .. }) => name,
        Ok(_) => "ok",
    };
    assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 0.0)), "hfov_deg");
    assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 179.5)), "hfov_deg");
    assert_eq!(
        name(CameraModel::pinhole_hfov(640, 480, f64::NAN)),
        "hfov_deg"
    );
    assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 179.0)), "ok");
    assert_eq!(name(CameraModel::pinhole_hfov(0, 480, 90.0)), "width");
    assert_eq!(name(CameraModel::pinhole_hfov(640, 0, 90.0)), "height");
    assert_eq!(
        name(CameraModel::fisheye_hfov(640, 480, 360.0, FK)),
        "hfov_deg"
    );
    assert_eq!(
        name(CameraModel::fisheye_hfov(640, 480, 300.0, FK)),
        "hfov_deg"
    );
    assert_eq!(
        name(CameraModel::fisheye_hfov(
            640,
            480,
            120.0,
            [f64::NAN, 0.0, 0.0, 0.0]
        )),
        "fisheye coefficients"
    );

    let check = |c: CameraModel| match c.validate() {
        Err(Invalid { name, .. }) => name,
        Ok(()) => "ok",
    };
    let good = radtan_cam();
    assert_eq!(check(good.clone()), "ok");
    assert_eq!(
        check(CameraModel {
            fx: -500.0,
            ..good.clone()
        }),
        "fx"
    );
    assert_eq!(
        check(CameraModel {
            fx: f64::INFINITY,
            ..good.clone()
        }),
        "fx"
    );
    assert_eq!(
        check(CameraModel {
            fy: 0.0,
            ..good.clone()
        }),
        "fy"
    );
    assert_eq!(
        check(CameraModel {
            cx: f64::NAN,
            ..good.clone()
        }),
        "cx"
    );
    assert_eq!(
        check(CameraModel {
            cx: 5000.0,
            ..good.clone()
        }),
        "cx"
    );
    assert_eq!(
        check(CameraModel {
            cy: -2000.0,
            ..good.clone()
        }),
        "cy"
    );
    assert_eq!(
        check(CameraModel {
            skew: f64::NAN,
            ..good.clone()
        }),
        "skew"
    );
    assert_eq!(
        check(CameraModel {
            width: 0,
            ..good.clone()
        }),
        "width"
    );
    assert_eq!(
        check(CameraModel {
            distortion: Distortion::RadTan {
                k1: 0.0,
                k2: 0.0,
                p1: f64::NAN,
                p2: 0.0,
                k3: 0.0
            },
            ..good.clone()
        }),
        "p1"
    );
    assert_eq!(
        check(CameraModel {
            distortion: Distortion::Fisheye {
                k1: 0.0,
                k2: 0.0,
                k3: 0.0,
                k4: f64::INFINITY
            },
            ..good
        }),
        "k4"
    );
    let msg = CameraModel::pinhole_hfov(640, 480, 200.0)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("hfov_deg") && msg.contains("200") && msg.contains("(0, 179]"),
        "{msg}"
    );
}

#[test]
fn invalid_models_do_not_panic() {
    let bad = CameraModel {
        fx: 0.0,
        fy: f64::NAN,
        distortion: Distortion::Fisheye {
            k1: f64::NAN,
            k2: 1e300,
            k3: -1e300,
            k4: 0.0,
        },
        ..pinhole_cam()
    };
    assert!(bad.project(&Vector3::new(0.1, 0.2, 1.0)).is_none());
    assert!(bad.unproject(&Vector2::new(10.0, 20.0)).is_none());
    let _ = bad.max_ray_angle();
    let _ = bad.hfov_deg();
    let weird = CameraModel {
        distortion: Distortion::RadTan {
            k1: 1e200,
            k2: -1e200,
            p1: 1e10,
            p2: -1e10,
            k3: 1e-300,
        },
        ..pinhole_cam()
    };
    let _ = weird.project(&Vector3::new(0.1, 0.2, 1.0));
    let _ = weird.unproject(&Vector2::new(10.0, 20.0));
    let _ = weird.max_ray_angle();
}

#[test]
fn k_matrix_layout() {
    let k = pinhole_cam().k_matrix();
    assert_eq!(k[(0, 0)], 573.8534);
    assert_eq!(k[(0, 1)], -0.6974);
    assert_eq!(k[(0, 2)], 406.0101);
    assert_eq!(k[(1, 1)], 575.0448);
    assert_eq!(k[(1, 2)], 309.0112);
    assert_eq!(k[(2, 2)], 1.0);
    assert_eq!(k[(1, 0)], 0.0);
}
