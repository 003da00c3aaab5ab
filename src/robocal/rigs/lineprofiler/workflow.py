"""The ``lineprofiler`` workflow's steps (:mod:`robocal.workflow`): simulate, summary, demo, ``compare``.

``load_input``, ``calibrate`` and ``to_result`` are :func:`.calibrate.load_input`,
:func:`.calibrate.calibrate_input` and :func:`.calibrate.to_result`; the report
is :func:`.report.build_report`. The declaration is ``RIG`` in :mod:`.cli`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robocal.io import atomic_write_text
from robocal.workflow import DemoContext, DemoOutcome

__all__ = ["simulate_files", "write_hand_eye_poses", "summary", "demo", "run_compare", "load_input",
           "calibrate_input"]


def load_input(path=None, *, bag=None, sphere_radius_mm=None, **bag_options):
    """The ``load_input`` step: an input file (:func:`.calibrate.load_input`), or with ``bag`` a recording's
    profiles and arm poses (:func:`.bag.load_bag_input`; ``path`` then optional: arm, radius, sign).
    ``sphere_radius_mm``: ``--sphere-radius`` [mm]."""
    if bag is not None:
        from robocal.rigs.lineprofiler.bag import load_bag_input

        radius = None if sphere_radius_mm is None else 1e-3 * float(sphere_radius_mm)
        return load_bag_input(bag, input_path=path, sphere_radius=radius, **bag_options)
    if path is None:
        from robocal.errors import InputError

        raise InputError("give an input file (fpdp_input.yaml, mct_input.yaml) or a recording with --bag FILE "
                         "--profiles TOPIC")
    from robocal.rigs.lineprofiler.calibrate import load_input as load_file

    return load_file(path)


def calibrate_input(inp, **options):
    """The ``calibrate`` step: :func:`.calibrate.calibrate_input`, with a recording's dropped profiles among
    the result's warnings."""
    from robocal.rigs.lineprofiler.calibrate import calibrate_input as calibrate

    cal = calibrate(inp, **options)
    notes = getattr(inp, "notes", None)
    if notes:
        cal.fpdp.warnings[0:0] = list(notes)
    return cal


def write_hand_eye_poses(out_dir: Path, rig, d, tr, rng: np.random.Generator, *, noise: bool = True) -> list[Path]:
    """Eye-in-hand pose lists ``gripper_poses.csv`` (T_base_gripper) and ``target_poses.csv`` (T_cam_target).

    The arm poses of the FPDP scan ``d`` with a wrist roll added (the P1R2P3 poses only turn about the
    vertical, degenerate for AX = XB); the "camera" is the laser frame L (``X = T_E_L = rig.X``) and the
    target the sphere centre's frame (``tr.sphere_centre``, axes of the world). With ``noise``: 1 mrad and
    0.2 mm per sensor pose. Returns the two paths.
    """
    from robocal.geometry import invert_transform, matrix_from_angle, matrix_from_rotvec, transform_from
    from robocal.rigs.lineprofiler.io import write_poses_csv

    n = len(d.q)
    Tg = rig.chain.fk(d.q) @ transform_from(matrix_from_angle("x", np.linspace(-0.6, 0.6, n)), np.zeros((n, 3)))
    Tc = invert_transform(rig.X) @ invert_transform(Tg) @ transform_from(np.eye(3), tr.sphere_centre)
    if noise:
        Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * 1e-3) @ Tc[:, :3, :3],
                            Tc[:, :3, 3] + rng.normal(size=(n, 3)) * 0.2e-3)
    t = np.arange(n) * 0.1
    return [write_poses_csv(Path(out_dir) / "gripper_poses.csv", Tg, t),
            write_poses_csv(Path(out_dir) / "target_poses.csv", Tc, t)]


def simulate_files(out_dir: Path, rng: np.random.Generator, *, poses: int = 16, noise_free: bool = False,
                   scan_profiles: int = 31, encoder_sigma: float = 0.0, seed=None, progress: bool = True,
                   **_) -> list[Path]:
    """``robocal lineprofiler simulate``: FPDP and MCT inputs and the hand-eye pose lists, with their truth.

    ``encoder_sigma`` in mm (P3 read-out noise of the MCT scan and line readings); ``seed`` only for the
    files' comment line.
    """
    from robocal.rigs.lineprofiler.io import write_profiles_csv
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    out = Path(out_dir)
    rig = default_rig()
    d, tr = simulate_fpdp(rig, rng, n_poses=poses, noise=not noise_free)
    paths = [write_profiles_csv(out / "fpdp_profiles.csv", d.profiles, d.q, angle_joints=(1,))]
    paths.append(atomic_write_text(
        out / "fpdp_input.yaml",
        "# robocal lineprofiler calibrate input (simulated, seed %s)\nunits: {length: mm}\n"
        "sphere_radius: %.4f\narm: p1r2p3\nprofiles: fpdp_profiles.csv\nsign: auto\n"
        "# truth: T_E_L translation [m] = %s\n" % (_seed_text(seed), 1e3 * d.sphere_radius,
                                                   np.round(rig.X[:3, 3], 6).tolist())))
    paths += write_hand_eye_poses(out, rig, d, tr, rng, noise=not noise_free)
    paths += _write_mct(out, rig, rng, seed=seed, scan_profiles=scan_profiles, encoder_sigma=encoder_sigma,
                        noise_free=noise_free)
    return [Path(p) for p in paths]


def _seed_text(seed) -> str:
    # the old command wrote "seed %d"; a run without --seed has none to name
    return "none" if seed is None else str(int(seed))


def _write_mct(out: Path, rig, rng, *, seed, scan_profiles: int, encoder_sigma: float, noise_free: bool) -> list:
    """The MCT procedure's files (tracker arc, line, block faces; block scan) and their input YAML."""
    from robocal.rigs.lineprofiler.io import write_block_faces_csv, write_profiles_csv, write_tracker_csv
    from robocal.rigs.lineprofiler.simulate import simulate_mct

    m, tr = simulate_mct(rig, rng, n_scan=scan_profiles, sigma_q3=1e-3 * encoder_sigma, noise=not noise_free)
    paths = [write_tracker_csv(out / "mct_arc.csv", m.q_arc, m.arc_T, angle_joints=(1,)),
             write_tracker_csv(out / "mct_line.csv", m.q_line, m.line_T, angle_joints=(1,)),
             write_block_faces_csv(out / "mct_block.csv", m.block_faces_T)]
    q_scan = np.tile(m.q_scan0, (len(m.scan_q3), 1))
    q_scan[:, -1] = m.scan_q3
    paths.append(write_profiles_csv(out / "mct_scan.csv", m.scan_profiles, q_scan, angle_joints=(1,)))
    paths.append(atomic_write_text(out / "mct_input.yaml", (
        "# robocal lineprofiler calibrate input, MCT method (simulated, seed %s)\nmethod: mct\n"
        "units: {length: mm, angle: deg}\narm: p1r2p3\n"
        "tracker:\n  arc: mct_arc.csv\n  line: mct_line.csv\n  block_faces: mct_block.csv\n"
        "  # sigma: %.4f  # per-axis tracker noise; default: pooled from the arc, line and face fits\n"
        "heights: {h0: %.4f, h1: %.4f, sigma: 0.02}\n"
        "# arm_sigma: {length: 0.3, angle: 0.1}  # uncertainty of P3's D-H row; default: taken as exact\n"
        "block_size: [%.3f, %.3f, %.3f]\n"
        "scan: mct_scan.csv\n%s\n# truth: T_E_L translation [m] = %s\n")
        % (_seed_text(seed), 1e3 * rig.tracker.sigma, 1e3 * m.h0, 1e3 * m.h1, *(1e3 * np.asarray(m.block_size)),
           (f"encoder_sigma: {encoder_sigma:g}  # P3 read-out noise per scan profile (simulated)"
            if encoder_sigma > 0 and not noise_free else
            "# encoder_sigma: 0.005  # P3 read-out noise per scan profile; default 0.005 (0: exact readings)"),
           np.round(tr.X[:3, 3], 6).tolist())))
    return paths


def summary(result) -> str:
    """``T_E_L translation [mm] (method): x +/- s, undetermined, ...``: the line ``calibrate`` prints."""
    t = result.estimate["T_E_L.translation"]
    st = result.std.get("T_E_L.translation") or [None] * 3
    return f"T_E_L translation [mm] ({result.method}): " + ", ".join(
        "undetermined" if v is None else f"{1e3 * v:.3f}" + ("" if s is None else f" +/- {1e3 * s:.3f}")
        for v, s in zip(t, st))


def _truth_of_refinement(cal, X_true):
    """NEES of the refined ``T_E_L`` against the simulated truth (undetermined components left out)."""
    from robocal.estimation import truth_check
    from robocal.geometry import rotvec_from_matrix

    X = cal.refined.X
    err = np.r_[rotvec_from_matrix(X[:3, :3] @ X_true[:3, :3].T), X[:3, 3] - X_true[:3, 3]]
    cov = np.array(cal.refined.cov[:6, :6], float)
    bad = ~np.isfinite(np.diag(cov))
    # an undetermined component: no variance, and no covariance with the others
    cov[bad, :] = 0.0
    cov[:, bad] = 0.0
    return truth_check(err, cov, names=("X.rx", "X.ry", "X.rz", "X.tx", "X.ty", "X.tz"))


def demo(ctx: DemoContext) -> DemoOutcome:
    """``robocal demo``: a simulated FPDP scan calibrated (truth checked by NEES) and the FPDP vs MCT re-run."""
    from robocal.progress import progress
    from robocal.report import truth_section
    from robocal.rigs.lineprofiler.calibrate import calibrate_sphere
    from robocal.rigs.lineprofiler.compare import run_comparison
    from robocal.handeye import transform_error
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.report import build_report, comparison_sections
    from robocal.rigs.lineprofiler.result import result_from
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    rig = default_rig()
    d, _ = simulate_fpdp(rig, ctx.rng)
    cal = calibrate_sphere(d.q, d.profiles, rig.chain, d.sphere_radius)
    result = result_from(cal)
    rot, _ = transform_error(cal.refined.X, rig.X)
    truth = _truth_of_refinement(cal, rig.X)
    cmp = run_comparison(rig, ctx.rng, progress=lambda it: progress(it, desc="FPDP vs MCT", enabled=ctx.progress))
    sections, rows = comparison_sections(cmp)
    rep = build_report(result)
    truth_section(rep.section("Truth check (simulated)"), truth.to_dict())
    undetermined_named = cal.refined.undetermined[:1] == ("Q.z",) or "X.ty" in cal.refined.undetermined
    passed = undetermined_named and truth.passed \
        and rows[-1]["max e_p [mm]"] < 0.25 and rows[0]["max e_p [mm]"] > 2 * rows[-1]["max e_p [mm]"]
    summary_ = {"refined rotation error": f"{np.rad2deg(rot):.4f} deg",
                "NEES": f"{truth.nees:.2f} / {truth.dof} (limit {truth.threshold:.1f})",
                "undetermined": ", ".join(cal.refined.undetermined) or "none",
                "MCT max e_p": f"{rows[-1]['max e_p [mm]']:.3f} mm", "FPDP max e_p": f"{rows[0]['max e_p [mm]']:.3f} mm"}
    return DemoOutcome(summary=summary_, passed=bool(passed), sections=rep.sections + sections, result=result)


def run_compare(args) -> int:
    """``robocal lineprofiler compare``: the seed's FPDP vs MCT comparison re-run in simulation."""
    from robocal.io import prepare_out_dir
    from robocal.progress import progress
    from robocal.report import Report
    from robocal.rigs.lineprofiler.compare import run_comparison
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.report import comparison_sections

    out = prepare_out_dir(args.out, "lineprofiler-compare")
    cmp = run_comparison(default_rig(), np.random.default_rng(args.seed), n_runs=args.runs, n_poses=args.poses,
                         progress=lambda it: progress(it, desc="experiments"))
    sections, rows = comparison_sections(cmp)
    rep = Report("lineprofiler: FPDP vs MCT", subtitle=f"{args.runs} x {args.poses} poses, seed {args.seed}")
    rep.extend(sections)
    print(f"wrote {rep.write(out / 'report.html')}")
    for r in rows:
        print(f"{r['method']:16s} e_v {r['max e_v']:.2e}  e_theta {r['max e_theta [deg]']:.3f} deg  "
              f"e_p {r['max e_p [mm]']:.3f} mm")
    return 0
