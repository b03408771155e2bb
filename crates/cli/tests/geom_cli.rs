//! The geometry subcommands, run as a user would: `--help`, real inputs, and bad inputs that
//! must fail with a one-line error naming the problem.

use std::path::{Path, PathBuf};
use std::process::Command;

use fewview_geom::io::{read_mesh, write_mesh, write_npy};
use fewview_geom::mesh::Mesh;
use fewview_scene::Image;

mod common;
use common::s;

/// Runs `fewview`: success, stdout, stderr.
fn fewview(args: &[&str]) -> (bool, String, String) {
    let out = common::fewview(args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const CAMERA: &str = r#"{"intrinsics": {"fx": 400, "fy": 400, "cx": 40, "cy": 30, "width": 80, "height": 60},
 "world_to_camera": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}"#;

#[test]
fn every_geometry_command_has_help() {
    for (cmd, flag) in [
        ("blend", "--mask-f"),
        ("depth-mesh", "--tau"),
        ("depth-points", "--subsample"),
        ("mcubes", "--iso"),
        ("register", "--voxel"),
        ("chamfer", "--max-dist"),
        ("pose-error", "--eps"),
    ] {
        let (ok, out, err) = fewview(&[cmd, "--help"]);
        assert!(ok, "{cmd} --help failed: {err}");
        assert!(out.contains(flag), "{cmd} --help lacks {flag}:\n{out}");
    }
}

fn two_planes_depth(dir: &Path) -> (PathBuf, PathBuf) {
    let mut d = vec![0f32; 80 * 60];
    for j in 0..60 {
        for i in 0..80 {
            d[j * 80 + i] = if i < 40 { 2.0 } else { 3.0 };
        }
    }
    let depth = dir.join("depth.npy");
    write_npy(&depth, &[60, 80], &d).unwrap();
    let cam = dir.join("cam.json");
    std::fs::write(&cam, CAMERA).unwrap();
    (depth, cam)
}

#[test]
fn depth_mesh_and_points_from_files() {
    let dir = tempfile::tempdir().unwrap();
    let (depth, cam) = two_planes_depth(dir.path());
    let out = dir.path().join("m.ply");
    let (ok, _, err) = fewview(&[
        "depth-mesh",
        "--depth",
        s(&depth),
        "--camera",
        s(&cam),
        "-o",
        s(&out),
    ]);
    assert!(ok, "{err}");
    let m = read_mesh(&out).unwrap();
    assert_eq!(m.vertices.len(), 80 * 60 - 60, "one edge column dropped");
    let unfiltered = dir.path().join("u.obj");
    let (ok, _, err) = fewview(&[
        "depth-mesh",
        "--depth",
        s(&depth),
        "--camera",
        s(&cam),
        "--tau",
        "0",
        "-o",
        s(&unfiltered),
    ]);
    assert!(ok, "{err}");
    assert_eq!(read_mesh(&unfiltered).unwrap().faces.len(), 2 * 79 * 59);
    let pts = dir.path().join("p.ply");
    let (ok, stdout, err) = fewview(&[
        "depth-points",
        "--depth",
        s(&depth),
        "--cameras",
        s(&cam),
        "--contract",
        "paper",
        "--subsample",
        "0.1",
        "--seed",
        "3",
        "-o",
        s(&pts),
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("\"b_near\":3.0"), "{stdout}");
    assert_eq!(
        read_mesh(&pts).unwrap().vertices.len(),
        ((80 * 60 - 60) as f64 * 0.1).round() as usize
    );
    // NaN depth: clear error, no output.
    let mut d = vec![1f32; 80 * 60];
    d[81] = f32::NAN;
    write_npy(&depth, &[60, 80], &d).unwrap();
    let bad = dir.path().join("bad.ply");
    let (ok, _, err) = fewview(&[
        "depth-mesh",
        "--depth",
        s(&depth),
        "--camera",
        s(&cam),
        "-o",
        s(&bad),
    ]);
    assert!(
        !ok && err.contains("NaN") && err.contains("(1, 1)"),
        "{err}"
    );
    assert!(!bad.exists());
    // Size mismatch between depth and camera.
    write_npy(&depth, &[10, 10], &[1.0; 100]).unwrap();
    let (ok, _, err) = fewview(&[
        "depth-mesh",
        "--depth",
        s(&depth),
        "--camera",
        s(&cam),
        "-o",
        s(&bad),
    ]);
    assert!(
        !ok && err.contains("10×10") && err.contains("80×60"),
        "{err}"
    );
}

#[test]
fn a_contraction_without_valid_depth_names_the_depth_files() {
    let dir = tempfile::tempdir().unwrap();
    let (depth, cam) = two_planes_depth(dir.path());
    write_npy(&depth, &[60, 80], &[0f32; 80 * 60]).unwrap();
    let out = dir.path().join("p.ply");
    let (ok, _, err) = fewview(&[
        "depth-points",
        "--depth",
        s(&depth),
        "--cameras",
        s(&cam),
        "--contract",
        "paper",
        "-o",
        s(&out),
    ]);
    assert!(
        !ok && err.contains("no valid depth") && err.contains(s(&depth)),
        "{err}"
    );
    assert!(!out.exists());
}

fn save(img: &Image, p: &Path) {
    img.save_png(p).unwrap();
}

/// `f.png`, `g.png` (flat colours (0.2, 0.4, 0.6) and (0.6, 0.4, 0.2)) and their masks
/// `mf.png` (columns left of `f_until`) and `mg.png` (columns from `g_from` on), in `dir`.
fn blend_inputs(dir: &Path, (w, h): (usize, usize), f_until: usize, g_from: usize) -> Vec<PathBuf> {
    let mut mf = Image::new(w, h, 1);
    let mut mg = Image::new(w, h, 1);
    for j in 0..h {
        for i in 0..w {
            mf.set(i, j, 0, (i < f_until) as u8 as f32);
            mg.set(i, j, 0, (i >= g_from) as u8 as f32);
        }
    }
    let paths: Vec<PathBuf> = ["f.png", "g.png", "mf.png", "mg.png"]
        .iter()
        .map(|n| dir.join(n))
        .collect();
    save(&Image::filled(w, h, &[0.2, 0.4, 0.6]), &paths[0]);
    save(&Image::filled(w, h, &[0.6, 0.4, 0.2]), &paths[1]);
    save(&mf, &paths[2]);
    save(&mg, &paths[3]);
    paths
}

#[test]
fn blend_writes_an_image_and_rejects_bad_masks() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (40, 30);
    let paths = blend_inputs(dir.path(), (w, h), 25, 15);
    let out = dir.path().join("o.png");
    for method in ["occlusion-aware", "poisson", "pyramid", "feather"] {
        let (ok, stdout, err) = fewview(&[
            "blend",
            "--f",
            s(&paths[0]),
            "--g",
            s(&paths[1]),
            "--mask-f",
            s(&paths[2]),
            "--mask-g",
            s(&paths[3]),
            "--method",
            method,
            "--levels",
            "2",
            "-o",
            s(&out),
        ]);
        assert!(ok, "{method}: {err}");
        assert!(stdout.contains("method"), "{stdout}");
        let o = Image::load(&out).unwrap();
        // Left of the overlap is f, right of it g.
        assert!((o.get(2, 5, 0) - 0.2).abs() < 0.01, "{method}");
        if method != "poisson" {
            assert!((o.get(38, 5, 0) - 0.6).abs() < 0.01, "{method}");
        }
    }
    let empty = dir.path().join("empty.png");
    save(&Image::new(w, h, 1), &empty);
    let (ok, _, err) = fewview(&[
        "blend",
        "--f",
        s(&paths[0]),
        "--g",
        s(&paths[1]),
        "--mask-f",
        s(&paths[2]),
        "--mask-g",
        s(&empty),
        "-o",
        s(&out),
    ]);
    assert!(!ok && err.contains("empty"), "{err}");
    let small = dir.path().join("small.png");
    save(&Image::filled(10, 10, &[1.0]), &small);
    let (ok, _, err) = fewview(&[
        "blend",
        "--f",
        s(&paths[0]),
        "--g",
        s(&paths[1]),
        "--mask-f",
        s(&small),
        "--mask-g",
        s(&paths[3]),
        "-o",
        s(&out),
    ]);
    assert!(!ok && err.contains("10×10"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
}

/// `-o o.jpg` used to get PNG bytes; σ = 10⁴ used to hang the feather blur.
#[test]
fn blend_refuses_a_non_png_output_and_takes_a_huge_sigma() {
    let dir = tempfile::tempdir().unwrap();
    let paths = blend_inputs(dir.path(), (20, 12), 12, 8);
    let blend = |out: &Path, sigma: &str| {
        fewview(&[
            "blend",
            "--f",
            s(&paths[0]),
            "--g",
            s(&paths[1]),
            "--mask-f",
            s(&paths[2]),
            "--mask-g",
            s(&paths[3]),
            "--method",
            "feather",
            "--sigma",
            sigma,
            "-o",
            s(out),
        ])
    };
    let jpg = dir.path().join("o.jpg");
    let (ok, _, err) = blend(&jpg, "8");
    assert!(
        !ok && err.contains("o.jpg") && err.contains(".png"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    assert!(!jpg.exists());
    let png = dir.path().join("o.PNG");
    let (ok, _, err) = blend(&png, "10000");
    assert!(ok, "{err}");
    let o = Image::load(&png).unwrap();
    assert!(o.data.iter().all(|v| v.is_finite()));
}

#[test]
fn mcubes_of_a_sphere_grid_is_watertight() {
    let dir = tempfile::tempdir().unwrap();
    let n = 24;
    let mut g = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let p = [i, j, k].map(|x| x as f32 - 11.5);
                g.push((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 8.0);
            }
        }
    }
    let grid = dir.path().join("g.npy");
    write_npy(&grid, &[n, n, n], &g).unwrap();
    let out = dir.path().join("s.ply");
    let (ok, stdout, err) = fewview(&[
        "mcubes",
        "--grid",
        s(&grid),
        "--voxel",
        "0.5",
        "--origin",
        "-1,-1,-1",
        "-o",
        s(&out),
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("\"watertight\":true"), "{stdout}");
    let m = read_mesh(&out).unwrap();
    assert!(m.signed_volume() > 0.0);
    write_npy(&grid, &[n * n * n], &g).unwrap();
    let (ok, _, err) = fewview(&["mcubes", "--grid", s(&grid), "-o", s(&out)]);
    assert!(!ok && err.contains("3-D"), "{err}");
}

fn plane(z: f32) -> Mesh {
    let n = 6;
    let mut v = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            v.push([i as f32 * 5.0, j as f32 * 5.0, z]);
        }
    }
    let mut f = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = (j * (n + 1) + i) as u32;
            let b = a + 1;
            let c = a + (n + 1) as u32;
            f.push([a, b, c + 1]);
            f.push([a, c + 1, c]);
        }
    }
    Mesh::new(v, f)
}

#[test]
fn chamfer_of_a_shifted_plane_and_a_non_manifold_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.ply");
    let b = dir.path().join("b.ply");
    write_mesh(&a, &plane(0.0)).unwrap();
    write_mesh(&b, &plane(2.0)).unwrap();
    let json = dir.path().join("c.json");
    let (ok, _, err) = fewview(&[
        "chamfer",
        "--pred",
        s(&b),
        "--gt",
        s(&a),
        "--protocol",
        "synthetic",
        "--samples",
        "20000",
        "--json",
        s(&json),
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let c = v["chamfer_l1"].as_f64().unwrap();
    assert!((c / 2.0 - 1.0).abs() < 0.01, "{c}");
    let (ok, stdout, err) = fewview(&["chamfer", "--pred", s(&b), "--gt", s(&a)]);
    assert!(ok, "{err}");
    assert!(stdout.contains("chamfer"), "{stdout}");
    let mut fin = plane(0.0);
    let extra = fin.vertices.len() as u32;
    fin.vertices.push([2.5, 0.0, 3.0]);
    fin.faces.push([0, 1, extra]); // edge 0–1 now has two faces on one side plus this one
    fin.faces.push([1, 0, extra]);
    let nm = dir.path().join("nm.obj");
    write_mesh(&nm, &fin).unwrap();
    let (ok, _, err) = fewview(&[
        "chamfer",
        "--pred",
        s(&nm),
        "--gt",
        s(&a),
        "--protocol",
        "synthetic",
    ]);
    assert!(
        !ok && err.contains("not manifold") && err.contains("nm.obj"),
        "{err}"
    );
}

/// A huge triangle (or a tiny density, or a huge --samples) used to allocate gigabytes.
#[test]
fn chamfer_refuses_more_samples_than_the_cap() {
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big.ply");
    let small = dir.path().join("a.ply");
    write_mesh(
        &big,
        &Mesh::new(
            vec![[0., 0., 0.], [10_000., 0., 0.], [0., 10_000., 0.]],
            vec![[0, 1, 2]],
        ),
    )
    .unwrap();
    write_mesh(&small, &plane(0.0)).unwrap();
    let runs: [&[&str]; 3] = [
        &["--pred", s(&big), "--gt", s(&small), "--density", "0.5"],
        &["--pred", s(&small), "--gt", s(&small), "--density", "1e-6"],
        &[
            "--pred",
            s(&small),
            "--gt",
            s(&small),
            "--protocol",
            "synthetic",
            "--samples",
            "100000000000",
        ],
    ];
    for extra in runs {
        let mut args = vec!["chamfer"];
        args.extend_from_slice(extra);
        let (ok, _, err) = fewview(&args);
        assert!(!ok && err.contains("allowed"), "{extra:?}: {err}");
        assert!(err.contains("density") || err.contains("samples"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    }
}

#[test]
fn pose_error_of_identical_poses_is_the_floor() {
    let dir = tempfile::tempdir().unwrap();
    let poses = r"[[[1,0,0,0],[0,1,0,0],[0,0,1,1],[0,0,0,1]],
                    [[0,0,1,0],[0,1,0,0],[-1,0,0,2],[0,0,0,1]],
                    [[0,-1,0,0],[1,0,0,0],[0,0,1,3],[0,0,0,1]]]";
    let p = dir.path().join("p.json");
    std::fs::write(&p, poses).unwrap();
    let (ok, stdout, err) = fewview(&["pose-error", "--est", s(&p), "--gt", s(&p)]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let floor = v["rotation_floor_deg_f64"].as_f64().unwrap();
    assert!((v["rotation_deg"].as_f64().unwrap() - floor).abs() < 1e-9);
    assert!((floor - 0.081028).abs() < 1e-6);
    let q = dir.path().join("q.json");
    std::fs::write(&q, "[[[1,0,0,0],[0,1,0,0],[0,0,1,1],[0,0,0,1]]]").unwrap();
    let (ok, _, err) = fewview(&["pose-error", "--est", s(&q), "--gt", s(&p)]);
    assert!(!ok && err.contains("1 estimated poses but 3"), "{err}");
}

/// ε ≥ 1 (or NaN) used to panic in the arccos clamp; a negative one gave NaN errors.
#[test]
fn pose_error_refuses_an_eps_outside_zero_one() {
    let dir = tempfile::tempdir().unwrap();
    let poses = r"[[[1,0,0,0],[0,1,0,0],[0,0,1,1],[0,0,0,1]],
                    [[0,0,1,0],[0,1,0,0],[-1,0,0,2],[0,0,0,1]]]";
    let p = dir.path().join("p.json");
    std::fs::write(&p, poses).unwrap();
    for eps in ["--eps=2", "--eps=NaN", "--eps=-1"] {
        let (ok, _, err) = fewview(&["pose-error", "--est", s(&p), "--gt", s(&p), eps]);
        assert!(
            !ok && err.contains("eps") && err.contains("[0, 1)"),
            "{eps}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    }
}

#[test]
fn register_the_bunny_fixture() {
    let fx = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../geom/tests/fixtures/registration");
    let dir = tempfile::tempdir().unwrap();
    let fixture: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fx.join("fixture.json")).unwrap()).unwrap();
    let pre = dir.path().join("pre.json");
    std::fs::write(&pre, fixture["prealignment"].to_string()).unwrap();
    let out = dir.path().join("moved.ply");
    let report = dir.path().join("r.json");
    let (source, target) = (fx.join("source.ply"), fx.join("target.ply"));
    // `fewview register` on the fixture with its pre-alignment and report, plus `extra`.
    let register = |extra: &[&str]| {
        let mut a = vec![
            "register",
            "--source",
            s(&source),
            "--target",
            s(&target),
            "--voxel",
            "0.008",
            "--prealign",
            s(&pre),
            "--report",
            s(&report),
        ];
        a.extend_from_slice(extra);
        fewview(&a)
    };
    let fine_icp = [
        "--icp-threshold=0.02",
        "--icp-threshold=0.01",
        "--icp-threshold=0.005",
        "--icp-threshold=0.003",
    ];
    let (ok, _, err) = register(&[fine_icp.as_slice(), &["-o", s(&out)]].concat());
    assert!(ok, "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert!(r["icp"]["fitness"].as_f64().unwrap() > 0.5, "{r}");
    assert_eq!(
        read_mesh(&out).unwrap().vertices.len() as u64,
        fixture["source_points"].as_u64().unwrap()
    );
    // The report names ICP's start; `--icp-start ransac` is Alg. 3 as written.
    let best_start = r["icp"]["start"].as_str().unwrap().to_string();
    assert!(
        ["ransac", "prealignment"].contains(&best_start.as_str()),
        "{r}"
    );
    let (ok, _, err) = register(&["--icp-start", "ransac"]);
    assert!(ok, "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(r["icp"]["start"], "ransac", "{r}");
    assert!(r["ransac"]["fitness"].as_f64().unwrap() > 0.0, "{r}");

    // With the local-plane denoising the rotation lands within the issue's 0.5°.
    let run = |radius| register(&[fine_icp.as_slice(), &["--denoise-radius", radius]].concat());
    let (ok, _, err) = run("0.016");
    assert!(ok, "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    // The angle of R_est R_trueᵀ: its trace is Σ R_est[i][j] R_true[i][j].
    let rows = |m: &serde_json::Value| -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| m[i][j].as_f64().unwrap()))
    };
    let (est, truth) = (
        rows(&r["transformation"]),
        rows(&fixture["true_source_to_target"]),
    );
    let norm = |m: &[[f64; 3]; 3]| m.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
    let dot: f64 = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| est[i][j] * truth[i][j])
        .sum();
    // Both are s·R with ‖s·R‖_F = s·√3.
    let trace = 3.0 * dot / (norm(&est) * norm(&truth));
    let cos = ((trace - 1.0) / 2.0).clamp(-1.0, 1.0);
    let degrees = cos.acos().to_degrees();
    assert!(degrees < 0.5, "rotation error {degrees}°");

    let (ok, _, err) = run("0");
    assert!(
        !ok && err.contains("--denoise-radius must be positive"),
        "{err}"
    );
}

/// NaN (and ∞, and out-of-range values) for these numbers used to be accepted and to run; they
/// are refused while the arguments are parsed, with a one-line error naming the value.
#[test]
fn non_finite_numbers_are_refused_while_parsing() {
    for (command, flag, value) in [
        ("blend", "--tolerance", "NaN"),
        ("blend", "--tolerance", "0"),
        ("depth-mesh", "--tau", "NaN"),
        ("depth-mesh", "--tau", "-1"),
        ("depth-points", "--tau", "inf"),
        ("depth-points", "--subsample", "NaN"),
        ("depth-points", "--subsample", "1.5"),
        ("chamfer", "--tau", "NaN"),
    ] {
        let (ok, _, err) = fewview(&[command, flag, value]);
        assert!(!ok, "{command} {flag} {value} was accepted");
        assert!(
            err.contains(value) && err.contains("expected a"),
            "{command} {flag} {value}: {err}"
        );
    }
}

/// `fewview` with arguments that need not be UTF-8: (success, stdout, stderr).
fn fewview_os(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fewview"))
        .args(args)
        .output()
        .expect("run fewview");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// An output path that is not UTF-8 used to panic after the mesh was written: the summary line
/// put the `PathBuf` into `json!`, which serde refuses unless it is UTF-8.
#[test]
fn non_utf8_output_paths_are_written_and_reported() {
    use std::ffi::OsStr;
    use std::os::unix::ffi::OsStrExt;

    let dir = tempfile::tempdir().unwrap();
    let (depth, cam) = two_planes_depth(dir.path());
    let mesh = dir.path().join(OsStr::from_bytes(b"m\xff.ply"));
    let (ok, stdout, err) = fewview_os(&[
        OsStr::new("depth-mesh"),
        OsStr::new("--depth"),
        depth.as_os_str(),
        OsStr::new("--camera"),
        cam.as_os_str(),
        OsStr::new("-o"),
        mesh.as_os_str(),
    ]);
    assert!(ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(stdout.contains("\"out\""), "{stdout}");
    assert!(!read_mesh(&mesh).unwrap().faces.is_empty());

    let n = 8;
    let grid: Vec<f32> = (0..n * n * n)
        .map(|i| {
            let p = [i / (n * n), (i / n) % n, i % n].map(|x| x as f32 - 3.5);
            (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 2.5
        })
        .collect();
    let grid_path = dir.path().join("g.npy");
    write_npy(&grid_path, &[n, n, n], &grid).unwrap();
    let sphere = dir.path().join(OsStr::from_bytes(b"s\xff.obj"));
    let (ok, stdout, err) = fewview_os(&[
        OsStr::new("mcubes"),
        OsStr::new("--grid"),
        grid_path.as_os_str(),
        OsStr::new("-o"),
        sphere.as_os_str(),
    ]);
    assert!(ok, "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(stdout.contains("\"watertight\":true"), "{stdout}");
    assert!(!read_mesh(&sphere).unwrap().faces.is_empty());
}

/// A report whose folder is missing used to fail only after the main output was written (blend's
/// image, register's moved cloud) or the work was done; every output path is now checked first,
/// with an error naming the flag and the path, and nothing is written.
#[test]
fn outputs_that_cannot_be_written_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let nodir = root.join("nodir");
    let paths = blend_inputs(root, (20, 12), 12, 8);
    let image = root.join("b.png");
    let stats = nodir.join("s.json");
    let (ok, _, err) = fewview(&[
        "blend",
        "--f",
        s(&paths[0]),
        "--g",
        s(&paths[1]),
        "--mask-f",
        s(&paths[2]),
        "--mask-g",
        s(&paths[3]),
        "--out",
        s(&image),
        "--stats",
        s(&stats),
    ]);
    assert!(!ok, "blend with a missing --stats folder succeeded");
    assert!(
        err.contains("--stats") && err.contains("nodir/s.json") && err.contains("does not exist"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    assert!(!image.exists(), "blend wrote its image before failing");

    let fx = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../geom/tests/fixtures/registration");
    let moved = root.join("r.ply");
    let report = nodir.join("r.json");
    let (ok, _, err) = fewview(&[
        "register",
        "--source",
        s(&fx.join("source.ply")),
        "--target",
        s(&fx.join("target.ply")),
        "--voxel",
        "0.008",
        "--out",
        s(&moved),
        "--report",
        s(&report),
    ]);
    assert!(!ok, "register with a missing --report folder succeeded");
    assert!(
        err.contains("--report") && err.contains("nodir/r.json"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
    assert!(
        !moved.exists(),
        "register wrote the moved cloud before failing"
    );

    // A folder where a file goes, and a file where a folder goes.
    let (depth, cam) = two_planes_depth(root);
    let (ok, _, err) = fewview(&[
        "depth-mesh",
        "--depth",
        s(&depth),
        "--camera",
        s(&cam),
        "-o",
        s(root),
    ]);
    assert!(
        !ok && err.contains("--out") && err.contains("is a folder"),
        "{err}"
    );
    let under_a_file = depth.join("m.ply");
    let (ok, _, err) = fewview(&[
        "depth-points",
        "--depth",
        s(&depth),
        "--cameras",
        s(&cam),
        "-o",
        s(&under_a_file),
    ]);
    assert!(
        !ok && err.contains("--out") && err.contains("depth.npy is not a folder"),
        "{err}"
    );
    let mesh = root.join("plane.ply");
    write_mesh(&mesh, &plane(0.0)).unwrap();
    let json = nodir.join("c.json");
    let (ok, stdout, err) = fewview(&[
        "chamfer",
        "--pred",
        s(&mesh),
        "--gt",
        s(&mesh),
        "--json",
        s(&json),
    ]);
    assert!(
        !ok && err.contains("--json") && err.contains("nodir/c.json"),
        "{err}"
    );
    assert!(
        stdout.is_empty(),
        "chamfer printed its report before failing: {stdout}"
    );
    assert!(!nodir.exists(), "nothing written");
}

/// The world-to-camera poses (row-major 4×4) of a COLMAP `images.txt`, by image name.
fn colmap_poses(images_txt: &Path) -> Vec<(String, [[f64; 4]; 4])> {
    let images = fewview_scene::colmap::text::read_images(images_txt).unwrap();
    images
        .iter()
        .map(|image| {
            let m = image.world_to_camera().unwrap().to_matrix4();
            let rows = std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]));
            (image.name.clone(), rows)
        })
        .collect()
}

/// A dataset folder as the truth: the estimate's cameras are found by name (here a shuffled
/// subset of the demo capture's own poses, so every error is at its floor), and a name the
/// dataset lacks is a one-line error.
#[test]
fn pose_error_takes_a_dataset_folders_views_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("capture");
    let (ok, _, err) = fewview(&["demo", "--width", "32", "--write-capture", s(&data)]);
    assert!(ok, "{err}");
    let mut poses = colmap_poses(&data.join("sparse/0/images.txt"));
    assert!(poses.len() >= 4, "{} views", poses.len());
    poses.reverse();
    poses.pop();
    let est = |names: &[(String, [[f64; 4]; 4])]| {
        let list: Vec<serde_json::Value> = names
            .iter()
            .map(|(n, m)| {
                let k = serde_json::json!({ "fx": 30.0, "fy": 30.0, "cx": 16.0, "cy": 12.0, "width": 32, "height": 24 });
                serde_json::json!({ "name": n, "intrinsics": k, "world_to_camera": m })
            })
            .collect();
        let path = dir.path().join("est.json");
        std::fs::write(&path, serde_json::Value::Array(list).to_string()).unwrap();
        path
    };
    let path = est(&poses);
    let (ok, stdout, err) = fewview(&["pose-error", "--est", s(&path), "--gt", s(&data)]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let floor = v["rotation_floor_deg_f64"].as_f64().unwrap();
    assert!(
        (v["rotation_deg"].as_f64().unwrap() - floor).abs() < 1e-6,
        "{v}"
    );
    assert!(
        v["relative"]["rotation_max_deg"].as_f64().unwrap() < 1e-4,
        "{v}"
    );
    assert!(
        v["relative"]["direction_max_deg"].as_f64().unwrap() < 1e-4,
        "{v}"
    );

    poses[0].0 = "missing.png".into();
    let path = est(&poses);
    let (ok, _, err) = fewview(&["pose-error", "--est", s(&path), "--gt", s(&data)]);
    assert!(!ok && err.contains("no view named missing.png"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "one-line error: {err}");
}
