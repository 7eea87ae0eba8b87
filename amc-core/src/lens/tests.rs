//! Every format, round trips, and the errors for broken files.

use super::document::flow_depth;
use super::*;
use crate::camera::{CameraModel, Distortion};
use approx::assert_relative_eq;

const OPENCV_YAML: &str = "%YAML:1.0
---
calibration_time: \"Mon 03 Jun 2024 10:12:01 CEST\"
image_width: 1920
image_height: 1080
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 1.4123456789012345e+03, 0., 9.5912e+02, 0.,
       1.4131e+03, 5.4233e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ -2.8e-01, 7.0000000000000007e-02, 1.0000000000000000e-04,
       -2.0000000000000001e-04, 0. ]
avg_reprojection_error: 3.1415e-01
";

const OPENCV_JSON: &str = r#"{
    "image_width": 1280,
    "image_height": 720,
    "camera_matrix": {
        "type_id": "opencv-matrix",
        "rows": 3,
        "cols": 3,
        "dt": "d",
        "data": [ 9.0e+02, 0.5, 6.4e+02, 0.0, 9.1e+02, 3.6e+02, 0.0, 0.0, 1.0 ]
    },
    "distortion_coefficients": {
        "type_id": "opencv-matrix",
        "rows": 4,
        "cols": 1,
        "dt": "d",
        "data": [ 0.05, -0.01, 0.002, -0.0005 ]
    },
    "distortion_model": "fisheye"
}"#;

const GYROFLOW: &str = r#"{
  "name": "GoPro_HERO9 Black_Wide_4by3",
  "note": "",
  "calibrated_by": "someone",
  "camera_brand": "GoPro",
  "camera_model": "HERO9 Black",
  "lens_model": "Wide",
  "camera_setting": "4:3",
  "calib_dimension": { "w": 2704, "h": 2028 },
  "orig_dimension": { "w": 2704, "h": 2028 },
  "output_dimension": { "w": 2704, "h": 2028 },
  "frame_readout_time": 10.0,
  "gyro_lpf": null,
  "input_horizontal_stretch": 1.0,
  "input_vertical_stretch": 1.0,
  "num_images": 14,
  "fps": 59.94,
  "crop": null,
  "official": false,
  "asymmetrical": false,
  "fisheye_params": {
    "RMS_error": 0.41,
    "camera_matrix": [ [ 1195.2, 0.0, 1351.5 ], [ 0.0, 1194.8, 1013.6 ], [ 0.0, 0.0, 1.0 ] ],
    "distortion_coeffs": [ 0.0405, 0.0213, -0.0094, 0.0017 ],
    "radial_distortion_limit": null
  },
  "identifier": "",
  "calibrator_version": "1.5.0",
  "date": "2023-03-01",
  "compatible_settings": [],
  "sync_settings": null,
  "distortion_model": null,
  "digital_lens": null,
  "digital_lens_params": null,
  "interpolations": null,
  "focal_length": null,
  "crop_factor": null,
  "global_shutter": false
}"#;

const PROJECT: &str = r#"{"model": "opencv", "width": 800, "height": 600, "fx": 600.5, "fy": 601.25,
        "cx": 399.5, "cy": 299.5, "skew": 0.25, "dist": [-0.28, 0.07, 0.0001, -0.0002]}"#;

/// The Kannala-Brandt (OpenCV fisheye) distortion with coefficients `k`.
fn fisheye(k: [f64; 4]) -> Distortion {
    Distortion::Fisheye {
        k1: k[0],
        k2: k[1],
        k3: k[2],
        k4: k[3],
    }
}

#[test]
fn project_format() {
    let cam = parse_lens(PROJECT).expect("valid");
    assert_eq!((cam.width, cam.height), (800, 600));
    assert_eq!(
        (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
        (600.5, 601.25, 399.5, 299.5, 0.25)
    );
    assert_eq!(
        cam.distortion,
        Distortion::RadTan {
            k1: -0.28,
            k2: 0.07,
            p1: 1e-4,
            p2: -2e-4,
            k3: 0.0
        }
    );
    let pin = parse_lens(
        r#"{"model":"pinhole","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#,
    )
    .expect("dist and skew are optional for pinhole");
    assert!(pin.is_pinhole());
    assert_eq!(pin.skew, 0.0);
    let zeros = r#"{"model":"pinhole","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5,"dist":[0,0,0,0,0]}"#;
    assert!(parse_lens(zeros).expect("zeros are fine").is_pinhole());
    let fish = r#"{"model":"fisheye","width":640,"height":480,"fx":300,"fy":300,"cx":319.5,"cy":239.5,"dist":[0.05,-0.01,0.002,-0.0005]}"#;
    assert_eq!(
        parse_lens(fish).expect("valid").distortion,
        fisheye([0.05, -0.01, 0.002, -0.0005])
    );
}

#[test]
fn project_round_trip() {
    let cams = [
        CameraModel {
            skew: -0.6974,
            ..CameraModel::pinhole(800, 600, 573.8534, 575.0448, 406.0101, 309.0112)
        },
        parse_lens(PROJECT).expect("valid"),
        CameraModel::fisheye_hfov(1280, 960, 190.0, [0.05, -0.01, 0.002, -0.0005]).expect("valid"),
        CameraModel {
            distortion: Distortion::RadTan {
                k1: 0.1 / 3.0,
                k2: 1e-17,
                p1: -0.0,
                p2: 2.0f64.sqrt(),
                k3: 0.0,
            },
            ..CameraModel::pinhole(1, 1, 1e-3, 1e7, 0.1, -0.7)
        },
    ];
    for cam in cams {
        let text = to_project_json(&cam);
        assert_eq!(parse_lens(&text).expect("own output parses"), cam, "{text}");
    }
}

#[test]
fn cc9_lens_file() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/cc9/lens.json"
    );
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("skipping cc9_lens_file: {path} not found");
        return;
    };
    let cam = parse_lens(&text).expect("cc9 lens parses");
    assert_eq!((cam.width, cam.height), (800, 600));
    assert!(cam.is_pinhole());
    assert_relative_eq!(cam.fx, 573.8534);
    assert_relative_eq!(cam.fy, 575.0448);
    assert_relative_eq!(cam.cx, 406.0101);
    assert_relative_eq!(cam.cy, 309.0112);
    assert_relative_eq!(cam.skew, -0.6974);
    assert_eq!(parse_lens(&to_project_json(&cam)).expect("round trip"), cam);
}

#[test]
fn opencv_yaml() {
    let cam = parse_lens(OPENCV_YAML).expect("OpenCV YAML parses");
    assert_eq!((cam.width, cam.height), (1920, 1080));
    assert_relative_eq!(cam.fx, 1412.3456789012345);
    assert_relative_eq!(cam.fy, 1413.1);
    assert_relative_eq!(cam.cx, 959.12);
    assert_relative_eq!(cam.cy, 542.33);
    assert_eq!(cam.skew, 0.0);
    match cam.distortion {
        Distortion::RadTan { k1, k2, p1, p2, k3 } => {
            assert_relative_eq!(k1, -0.28);
            assert_relative_eq!(k2, 0.07);
            assert_relative_eq!(p1, 1e-4);
            assert_relative_eq!(p2, -2e-4);
            assert_eq!(k3, 0.0);
        }
        ref d => panic!("expected radtan, got {d:?}"),
    }
    // Nested-list forms, image_size and a fisheye flag.
    let yaml = "%YAML:1.0\nimage_size: [ 640, 480 ]\nfisheye: true\ncamera_matrix: [[300., 0., 320.], [0., 301., 240.], [0., 0., 1.]]\ndistortion_coefficients: [[0.1], [0.01], [-0.002], [0.0003]]\n";
    let cam = parse_lens(yaml).expect("valid");
    assert_eq!((cam.width, cam.height), (640, 480));
    assert_eq!(cam.distortion, fisheye([0.1, 0.01, -0.002, 0.0003]));
}

#[test]
fn opencv_json() {
    let cam = parse_lens(OPENCV_JSON).expect("OpenCV JSON parses");
    assert_eq!((cam.width, cam.height), (1280, 720));
    assert_eq!(
        (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
        (900.0, 910.0, 640.0, 360.0, 0.5)
    );
    assert_eq!(cam.distortion, fisheye([0.05, -0.01, 0.002, -0.0005]));
    // 4 coefficients without a fisheye marker are k1 k2 p1 p2.
    let radtan = OPENCV_JSON.replace(
        "\"distortion_model\": \"fisheye\"",
        "\"width\": 1280, \"height\": 720",
    );
    let radtan = radtan.replace("\"image_width\": 1280,\n    \"image_height\": 720,", "");
    let cam = parse_lens(&radtan).expect("valid");
    assert_eq!(
        cam.distortion,
        Distortion::RadTan {
            k1: 0.05,
            k2: -0.01,
            p1: 0.002,
            p2: -0.0005,
            k3: 0.0
        }
    );
}

#[test]
fn gyroflow_profile() {
    let cam = parse_lens(GYROFLOW).expect("Gyroflow profile parses");
    assert_eq!((cam.width, cam.height), (2704, 2028));
    assert_eq!(
        (cam.fx, cam.fy, cam.cx, cam.cy, cam.skew),
        (1195.2, 1194.8, 1351.5, 1013.6, 0.0)
    );
    assert_eq!(cam.distortion, fisheye([0.0405, 0.0213, -0.0094, 0.0017]));
    let other = GYROFLOW.replace(
        "\"distortion_model\": null",
        "\"distortion_model\": \"poly5\"",
    );
    let err = parse_lens(&other).unwrap_err();
    assert!(matches!(err, LensError::UnsupportedModel { .. }), "{err}");
    assert!(err.to_string().contains("poly5"), "{err}");
    let explicit = GYROFLOW.replace(
        "\"distortion_model\": null",
        "\"distortion_model\": \"opencv_fisheye\"",
    );
    assert!(parse_lens(&explicit).is_ok());
}

fn err(text: &str) -> String {
    match parse_lens(text) {
        Ok(cam) => panic!("expected an error, got {cam:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn garbage_is_rejected() {
    for text in [
        "",
        "   \n",
        "hello world",
        "{{{{",
        "[1, 2, 3]",
        "\u{0}\u{1}\u{2}",
        "{\"a\": 1}",
        "<?xml version=\"1.0\"?>\n<opencv_storage/>",
        "- a\n- b",
        "%YAML:1.0\n---\n",
    ] {
        let _ = err(text);
    }
    assert!(err("{\"model\": \"pinhole\", ").contains("invalid JSON"));
    assert!(err("{\"a\": 1}").contains("unrecognised lens file"));
    assert!(err("<?xml version=\"1.0\"?>").contains("XML"));
    // Deeply nested input must not overflow the stack.
    let deep = "[".repeat(100_000);
    let _ = err(&deep);
    let deep_yaml = format!("camera_matrix: {}", "[".repeat(100_000));
    assert!(err(&deep_yaml).contains("nested"));
    let deep_map = format!("camera_matrix: {}", "{a: ".repeat(100_000));
    assert!(err(&deep_map).contains("nested"));
    let _ = err(&"- ".repeat(300_000));
    assert!(err(&" ".repeat(2 << 20)).contains("bytes"));
    // Brackets inside quotes and comments do not count.
    assert_eq!(flow_depth("a: \"[[[[\" # {{{{\nb: [[1], '[[']"), 2);
}

#[test]
fn missing_keys_are_named() {
    let no_fx = r#"{"model":"pinhole","width":640,"height":480,"fy":500,"cx":319.5,"cy":239.5}"#;
    assert!(err(no_fx).contains("`fx`"), "{}", err(no_fx));
    let no_h = r#"{"model":"pinhole","width":640,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#;
    assert!(err(no_h).contains("`height`"));
    let no_dist =
        r#"{"model":"fisheye","width":640,"height":480,"fx":500,"fy":500,"cx":319.5,"cy":239.5}"#;
    assert!(err(no_dist).contains("dist"));
    let no_size = OPENCV_YAML.replace("image_width: 1920\nimage_height: 1080\n", "");
    assert_eq!(parse_lens(&no_size), Err(LensError::MissingImageSize));
    assert!(err(&no_size).contains("image size"));
    let no_k = OPENCV_YAML.replace("camera_matrix", "camera_matrx");
    assert!(err(&no_k).contains("`camera_matrix`"), "{}", err(&no_k));
    let no_dim = GYROFLOW.replace("calib_dimension", "calib_dim");
    assert!(err(&no_dim).contains("`calib_dimension`"));
    let no_coeffs = GYROFLOW.replace("distortion_coeffs", "distortion");
    assert!(err(&no_coeffs).contains("fisheye_params.distortion_coeffs"));
}

#[test]
fn wrong_values_are_explained() {
    let three = PROJECT.replace("[-0.28, 0.07, 0.0001, -0.0002]", "[-0.28, 0.07, 0.0001]");
    assert!(
        err(&three).contains("4 or 5 coefficients"),
        "{}",
        err(&three)
    );
    let pin_dist = PROJECT.replace("\"opencv\"", "\"pinhole\"");
    assert!(err(&pin_dist).contains("pinhole"));
    let fish5 = PROJECT
        .replace("\"opencv\"", "\"fisheye\"")
        .replace("-0.0002]", "-0.0002, 0.1]");
    assert!(
        err(&fish5).contains("4 fisheye coefficients"),
        "{}",
        err(&fish5)
    );
    let unknown = PROJECT.replace("\"opencv\"", "\"kb8\"");
    assert!(err(&unknown).contains("kb8"));
    let rational = OPENCV_YAML.replace("cols: 5", "cols: 8").replace(
        "-2.0000000000000001e-04, 0. ]",
        "-2.0000000000000001e-04, 0., 0.1, 0.2, 0.3 ]",
    );
    let msg = err(&rational);
    assert!(
        msg.contains("k1 k2 p1 p2") && msg.contains("rational"),
        "{msg}"
    );
    let rows_mismatch = OPENCV_YAML.replace("cols: 5", "cols: 4");
    assert!(err(&rows_mismatch).contains("rows x cols"));
    let neg_f = PROJECT.replace("600.5", "-600.5");
    let msg = err(&neg_f);
    assert!(matches!(parse_lens(&neg_f), Err(LensError::Camera(_))));
    assert!(msg.contains("fx") && msg.contains("-600.5"), "{msg}");
    let text_f = PROJECT.replace("600.5", "\"big\"");
    assert!(err(&text_f).contains("`fx` must be a finite number"));
    let bad_w = PROJECT.replace("800", "800.5");
    assert!(err(&bad_w).contains("`width`"));
    let zero_w = PROJECT.replace("800", "0");
    assert!(err(&zero_w).contains("`width`"));
    let bad_k = GYROFLOW.replace("[ 0.0, 0.0, 1.0 ]", "[ 0.0, 0.0, 2.0 ]");
    assert!(err(&bad_k).contains("[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]"));
    let stretched = GYROFLOW.replace(
        "\"input_horizontal_stretch\": 1.0",
        "\"input_horizontal_stretch\": 1.33",
    );
    assert!(err(&stretched).contains("input_horizontal_stretch"));
    let yaml_model = OPENCV_YAML.replace("flags: 0", "distortion_model: omnidir");
    assert!(err(&yaml_model).contains("omnidir"));
    let far_cx = PROJECT.replace("399.5", "1e6");
    assert!(err(&far_cx).contains("cx"));
}

#[test]
fn readout_from_the_project_json_and_gyroflow() {
    // Absent: not known (the caller falls back to a global shutter).
    assert_eq!(parse_lens_file(PROJECT).expect("valid").readout_ms, None);
    assert_eq!(
        parse_lens_file(OPENCV_YAML).expect("valid").readout_ms,
        None
    );
    let with = PROJECT.replace("\"dist\"", "\"readout_ms\": 14.5, \"dist\"");
    let lens = parse_lens_file(&with).expect("valid");
    assert_eq!(lens.readout_ms, Some(14.5));
    assert_eq!(lens.camera, parse_lens(PROJECT).unwrap());
    let null = PROJECT.replace("\"dist\"", "\"readout_ms\": null, \"dist\"");
    assert_eq!(parse_lens_file(&null).unwrap().readout_ms, None);
    // Gyroflow's frame_readout_time is in milliseconds too.
    assert_eq!(parse_lens_file(GYROFLOW).unwrap().readout_ms, Some(10.0));
    let unknown = GYROFLOW.replace(
        "\"frame_readout_time\": 10.0",
        "\"frame_readout_time\": null",
    );
    assert_eq!(parse_lens_file(&unknown).unwrap().readout_ms, None);
    // Out of range or not a number: the key, the value and the range.
    for (text, key, found) in [
        (
            PROJECT.replace("\"dist\"", "\"readout_ms\": 150, \"dist\""),
            "readout_ms",
            "150",
        ),
        (
            PROJECT.replace("\"dist\"", "\"readout_ms\": \"fast\", \"dist\""),
            "readout_ms",
            "fast",
        ),
        (
            GYROFLOW.replace(
                "\"frame_readout_time\": 10.0",
                "\"frame_readout_time\": -8.0",
            ),
            "frame_readout_time",
            "-8",
        ),
    ] {
        let e = parse_lens_file(&text).unwrap_err();
        assert!(matches!(e, LensError::InvalidValue { .. }), "{e}");
        let msg = e.to_string();
        assert!(msg.contains(key) && msg.contains(found), "{msg}");
        assert!(msg.contains("0..=100") || msg.contains("number"), "{msg}");
    }
}

#[test]
fn readout_round_trips_through_the_project_json() {
    let camera = parse_lens(PROJECT).unwrap();
    for readout_ms in [None, Some(0.0), Some(16.7), Some(100.0)] {
        let lens = LensFile {
            camera: camera.clone(),
            readout_ms,
        };
        let text = lens.to_project_json();
        assert_eq!(
            parse_lens_file(&text).expect("own output parses"),
            lens,
            "{text}"
        );
    }
    assert!(!to_project_json(&camera).contains("readout_ms"));
}
