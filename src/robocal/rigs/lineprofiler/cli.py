"""Command line of the ``lineprofiler`` rig and of ``robocal handeye`` (thin wiring over the library)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from robocal.cli import (
    DemoOutcome,
    RawHelp,
    Rig,
    add_out_argument,
    add_seed_argument,
    examples_epilog,
    prepare_out_dir,
    write_run,
)
from robocal.io import CalibrationResult, atomic_write_text, hash_inputs
from robocal.cli._common import add_accept_implausible_argument
from robocal.progress import progress
from robocal.report import Report, Section

EXAMPLES = Path("examples/lineprofiler")


def _int_at_least(minimum: int, why: str):
    """argparse type: an integer >= ``minimum`` (``why`` says what needs it)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum} ({why}), got {v}")
        return v
    return parse


def _length_mm(text: str) -> float:
    """argparse type: a finite length >= 0 in mm."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of mm, got {text!r}") from None
    if not (np.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite length >= 0 in mm, got {text}")
    return v


# ----------------------------------------------------------------------------- lineprofiler
def _simulate(args) -> int:
    from robocal.geometry import invert_transform
    from robocal.rigs.lineprofiler.io import write_poses_csv, write_profiles_csv
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    out = prepare_out_dir(args.out, "lineprofiler-simulate")
    rng = np.random.default_rng(args.seed)
    rig = default_rig()
    d, tr = simulate_fpdp(rig, rng, n_poses=args.poses, noise=not args.noise_free)
    write_profiles_csv(out / "fpdp_profiles.csv", d.profiles, d.q, angle_joints=(1,))
    atomic_write_text(out / "fpdp_input.yaml",
                      "# robocal lineprofiler calibrate input (simulated, seed %d)\nunits: {length: mm}\n"
                      "sphere_radius: %.4f\narm: p1r2p3\nprofiles: fpdp_profiles.csv\nsign: auto\n"
                      "# truth: T_E_L translation [m] = %s\n" % (args.seed, 1e3 * d.sphere_radius,
                                                                 np.round(rig.X[:3, 3], 6).tolist()))
    # eye-in-hand pose lists for `robocal handeye calibrate`: the P1R2P3 poses only turn about
    # the vertical (degenerate for AX = XB), so a wrist roll is added
    from robocal.geometry import rotx, transform_from

    n = len(d.q)
    Tg = rig.chain.fk(d.q) @ transform_from(rotx(np.linspace(-0.6, 0.6, n)), np.zeros((n, 3)))
    Tc = invert_transform(rig.X) @ invert_transform(Tg) @ transform_from(np.eye(3), tr.sphere_centre)
    if not args.noise_free:
        from robocal.geometry import matrix_from_rotvec

        Tc = transform_from(matrix_from_rotvec(rng.normal(size=(n, 3)) * 1e-3) @ Tc[:, :3, :3],
                            Tc[:, :3, 3] + rng.normal(size=(n, 3)) * 0.2e-3)
    write_poses_csv(out / "gripper_poses.csv", Tg, np.arange(len(Tg)) * 0.1)
    write_poses_csv(out / "target_poses.csv", Tc, np.arange(len(Tc)) * 0.1)
    _write_mct(out, rig, rng, args)
    print(f"wrote {out}/fpdp_input.yaml, fpdp_profiles.csv, gripper_poses.csv, target_poses.csv, "
          "mct_input.yaml, mct_arc.csv, mct_line.csv, mct_block.csv, mct_scan.csv")
    return 0


def _write_mct(out: Path, rig, rng, args) -> None:
    """The MCT procedure's files (tracker arc, line, block faces; block scan) and their input YAML."""
    from robocal.rigs.lineprofiler.io import write_block_faces_csv, write_profiles_csv, write_tracker_csv
    from robocal.rigs.lineprofiler.simulate import simulate_mct

    m, tr = simulate_mct(rig, rng, n_scan=args.scan_profiles, sigma_q3=1e-3 * args.encoder_sigma,
                         noise=not args.noise_free)
    write_tracker_csv(out / "mct_arc.csv", m.q_arc, m.arc_T, angle_joints=(1,))
    write_tracker_csv(out / "mct_line.csv", m.q_line, m.line_T, angle_joints=(1,))
    write_block_faces_csv(out / "mct_block.csv", m.block_faces_T)
    q_scan = np.tile(m.q_scan0, (len(m.scan_q3), 1))
    q_scan[:, -1] = m.scan_q3
    write_profiles_csv(out / "mct_scan.csv", m.scan_profiles, q_scan, angle_joints=(1,))
    atomic_write_text(out / "mct_input.yaml", (
        "# robocal lineprofiler calibrate input, MCT method (simulated, seed %d)\nmethod: mct\n"
        "units: {length: mm, angle: deg}\narm: p1r2p3\n"
        "tracker:\n  arc: mct_arc.csv\n  line: mct_line.csv\n  block_faces: mct_block.csv\n"
        "  # sigma: %.4f  # per-axis tracker noise; default: pooled from the arc, line and face fits\n"
        "heights: {h0: %.4f, h1: %.4f, sigma: 0.02}\n"
        "# arm_sigma: {length: 0.3, angle: 0.1}  # uncertainty of P3's D-H row; default: taken as exact\n"
        "block_size: [%.3f, %.3f, %.3f]\n"
        "scan: mct_scan.csv\n%s\n# truth: T_E_L translation [m] = %s\n")
        % (args.seed, 1e3 * rig.tracker.sigma, 1e3 * m.h0, 1e3 * m.h1, *(1e3 * np.asarray(m.block_size)),
           (f"encoder_sigma: {args.encoder_sigma:g}  # P3 read-out noise per scan profile (simulated)"
            if args.encoder_sigma > 0 and not args.noise_free else
            "# encoder_sigma: 0.005  # P3 read-out noise per scan profile; default 0.005 (0: exact readings)"),
           np.round(tr.X[:3, 3], 6).tolist()))


def _calibrate(args) -> int:
    from robocal.rigs.lineprofiler.calibrate import calibrate_file, report_from, result_from

    cal, inputs = calibrate_file(args.input, accept_implausible=args.accept_implausible)
    result = result_from(cal, inputs)
    out = prepare_out_dir(args.out, "lineprofiler-calibrate")
    write_run(out, result, report_from(result, cal))
    t = result.estimate["T_E_L.translation"]
    st = result.std.get("T_E_L.translation") or [None] * 3
    print(f"T_E_L translation [mm] ({result.method}): " + ", ".join(
        "undetermined" if v is None else f"{1e3 * v:.3f}" + ("" if s is None else f" +/- {1e3 * s:.3f}")
        for v, s in zip(t, st)))
    return 0


def _report(args) -> int:
    from robocal.rigs.lineprofiler.calibrate import load_result_report

    out = prepare_out_dir(args.out, "lineprofiler-report")
    print(f"wrote {load_result_report(args.result).write(out / 'report.html')}")
    return 0


def _comparison_sections(cmp) -> list[Section]:
    from robocal.rigs.lineprofiler.compare import plot_comparison

    s = Section("FPDP vs MCT (seed §4.3, 3 x 16 poses, simulated)")
    ax = plot_comparison(cmp)
    s.figure(ax[0].figure, "repeatability errors against the mean of the runs (seed Fig. 5)")
    rows = []
    for k in cmp.X:
        rows.append({"method": k, "max e_v": cmp.e_v[k].max(), "max e_theta [deg]": np.rad2deg(cmp.e_theta[k]).max(),
                     "max e_p [mm]": 1e3 * cmp.e_p[k].max(),
                     "rot err vs truth [deg]": np.rad2deg(cmp.err_true_rot[k]).mean(),
                     "t err vs truth [mm]": 1e3 * cmp.err_true_t[k].mean()})
    s.table(rows, digits=3)
    s.text(f"FPDP cannot determine {', '.join(cmp.undetermined)} on the P1R2P3 arm; its e_p uses the other "
           "components. 'FPDP+refine' is the geometric refinement on every profile point with the joint "
           "readings' noise modelled (one joint correction per pose); 'refine, q exact' takes the readings as "
           "exact, so a pose's reading error, shared by all its points, is averaged like point noise: it is "
           "barely more repeatable than FPDP and its std is several times too small. The seed reports MCT "
           "e_v < 0.001, e_theta <= 0.07 deg, e_p <= 0.25 mm and FPDP translation errors above 5 mm.")
    return [s], rows


def _compare(args) -> int:
    from robocal.rigs.lineprofiler.compare import run_comparison
    from robocal.rigs.lineprofiler.model import default_rig

    out = prepare_out_dir(args.out, "lineprofiler-compare")
    cmp = run_comparison(default_rig(), np.random.default_rng(args.seed), n_runs=args.runs, n_poses=args.poses,
                         progress=lambda it: progress(it, desc="experiments"))
    sections, rows = _comparison_sections(cmp)
    rep = Report("lineprofiler: FPDP vs MCT", subtitle=f"{args.runs} x {args.poses} poses, seed {args.seed}")
    rep.extend(sections)
    print(f"wrote {rep.write(out / 'report.html')}")
    for r in rows:
        print(f"{r['method']:16s} e_v {r['max e_v']:.2e}  e_theta {r['max e_theta [deg]']:.3f} deg  "
              f"e_p {r['max e_p [mm]']:.3f} mm")
    return 0


def _add_lineprofiler(parser) -> None:
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")
    p = sub.add_parser("simulate", help="write simulated FPDP and MCT input files (and hand-eye pose lists)",
                       formatter_class=RawHelp,
                       epilog=examples_epilog("robocal lineprofiler simulate --out lineprofiler-sim --seed 1"))
    add_out_argument(p)
    add_seed_argument(p)
    p.add_argument("--poses", type=_int_at_least(5, "FPDP fits X and the sphere centre from 5 or more"),
                   default=16, help="number of arm poses of the FPDP sphere scan")
    p.add_argument("--noise-free", action="store_true", help="no measurement noise")
    p.add_argument("--scan-profiles", type=_int_at_least(3, "MCT's block scan needs a P3 stroke of 3 or more"),
                   default=31, help="profiles in the MCT block scan")
    p.add_argument("--encoder-sigma", type=_length_mm, default=0.0, metavar="MM",
                   help="P3 encoder read-out noise of the MCT scan and line readings, in mm (default 0: exact)")
    p.set_defaults(func=_simulate)
    p = sub.add_parser("calibrate", help="FPDP + geometric refinement, or MCT, from an input YAML",
                       formatter_class=RawHelp,
                       epilog=examples_epilog(f"robocal lineprofiler calibrate {EXAMPLES}/fpdp_input.yaml --out lineprofiler-cal",
                                              f"robocal lineprofiler calibrate {EXAMPLES}/mct_input.yaml --out lineprofiler-mct"))
    p.add_argument("input", type=Path, help="input YAML: sphere radius, arm, profiles CSV (FPDP); or 'method: mct' "
                                            "with tracker, heights, block and scan files (see docs/rigs/lineprofiler.md)")
    add_accept_implausible_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_calibrate)
    p = sub.add_parser("report", help="re-render report.html from a result.json", formatter_class=RawHelp,
                       epilog=examples_epilog("robocal lineprofiler report lineprofiler-cal/result.json --out lineprofiler-report"))
    p.add_argument("result", type=Path, help="result.json written by 'robocal lineprofiler calibrate'")
    add_out_argument(p)
    p.set_defaults(func=_report)
    p = sub.add_parser("compare", help="simulated re-run of the seed's FPDP vs MCT comparison",
                       formatter_class=RawHelp, epilog=examples_epilog("robocal lineprofiler compare --out lineprofiler-compare"))
    add_out_argument(p)
    add_seed_argument(p)
    p.add_argument("--runs", type=_int_at_least(2, "the spread of repeated calibrations needs 2 or more"),
                   default=3, help="repeated experiments (the seed's 3); e_v, e_theta, e_p against their mean")
    p.add_argument("--poses", type=_int_at_least(5, "FPDP fits X and the sphere centre from 5 or more"),
                   default=16, help="arm poses per FPDP experiment (the seed's 16)")
    p.set_defaults(func=_compare)


def _demo(ctx) -> DemoOutcome:
    from robocal.rigs.lineprofiler.calibrate import calibrate_sphere, report_from, result_from
    from robocal.rigs.lineprofiler.compare import run_comparison
    from robocal.rigs.lineprofiler.handeye import transform_error
    from robocal.rigs.lineprofiler.model import default_rig
    from robocal.rigs.lineprofiler.simulate import simulate_fpdp

    rig = default_rig()
    d, _ = simulate_fpdp(rig, ctx.rng)
    cal = calibrate_sphere(d.q, d.profiles, rig.chain, d.sphere_radius)
    result = result_from(cal)
    rot, _ = transform_error(cal.refined.X, rig.X)
    cmp = run_comparison(rig, ctx.rng, progress=lambda it: progress(it, desc="FPDP vs MCT", enabled=ctx.progress))
    sections, rows = _comparison_sections(cmp)
    rep = report_from(result, cal)
    passed = (cal.refined.undetermined[:1] == ("Q.z",) or "X.ty" in cal.refined.undetermined) and rot < 2e-3 \
        and rows[-1]["max e_p [mm]"] < 0.25 and rows[0]["max e_p [mm]"] > 2 * rows[-1]["max e_p [mm]"]
    summary = {"refined rotation error": f"{np.rad2deg(rot):.4f} deg",
               "undetermined": ", ".join(cal.refined.undetermined) or "none",
               "MCT max e_p": f"{rows[-1]['max e_p [mm]']:.3f} mm", "FPDP max e_p": f"{rows[0]['max e_p [mm]']:.3f} mm"}
    return DemoOutcome(summary=summary, passed=bool(passed), sections=rep.sections + sections, result=result)


RIG = Rig(name="lineprofiler", help="hand-eye calibration of an arm-mounted line laser (seed 004: FPDP, MCT)",
          description="Line-laser profiler hand-eye calibration: FPDP (sphere, linear), geometric refinement on all "
                      "profile points, MCT (laser tracker and standard block), FPDP vs MCT re-run in "
                      "simulation.\n\n" + examples_epilog(
                          "robocal lineprofiler simulate --out lineprofiler-sim",
                          f"robocal lineprofiler calibrate {EXAMPLES}/fpdp_input.yaml --out lineprofiler-cal",
                          f"robocal lineprofiler calibrate {EXAMPLES}/mct_input.yaml --out lineprofiler-mct",
                          "robocal lineprofiler report lineprofiler-cal/result.json --out lineprofiler-report",
                          "robocal lineprofiler compare --out lineprofiler-compare"),
          add_commands=_add_lineprofiler, demo=_demo)


# ----------------------------------------------------------------------------- handeye
def _stages(desc: str, n: int):
    """A stage bar on a terminal (10^4 poses: ~8 s to read, ~15 s to solve): ``tick()`` starts the next stage."""
    it = iter(progress(range(n), desc=desc, total=n))
    return lambda: next(it, None)


def _load_pose_pair(args):
    """``(T_base_gripper, T_cam_target)`` from the two pose lists, the robot stream resampled at the
    sensor's timestamps when both have timestamps that differ. Errors name the file(s)."""
    from robocal.errors import RobocalError, ShapeError
    from robocal.rigs.lineprofiler.io import interpolate_poses, load_poses

    Tg, tg = load_poses(args.gripper_poses)
    Tc, tc = load_poses(args.target_poses)
    if tg is not None and tc is not None and (len(tg) != len(tc) or np.any(np.abs(tg - tc) > 1e-9)):
        try:
            Tg = interpolate_poses(tg, Tg, tc)
        except RobocalError as exc:
            raise exc.with_source(f"{args.gripper_poses} resampled at the times of {args.target_poses}") from None
    elif len(Tg) != len(Tc):
        raise ShapeError(f"{args.gripper_poses} has {len(Tg)} poses but {args.target_poses} has {len(Tc)}: "
                         "without timestamps in both lists the counts must match (pose i with pose i)")
    return Tg, Tc


def _solve_named(args, fn, *a, **kw):
    """Run a hand-eye solver; its errors (too few poses, degenerate motions, ...) name the two files."""
    from robocal.errors import ImplausibleInputError, RobocalError

    try:
        return fn(*a, **kw)
    except ImplausibleInputError:
        raise                                   # names the file in its message already
    except RobocalError as exc:
        raise exc.with_source(f"{args.gripper_poses} + {args.target_poses}") from None


def _pose_list_arguments(p) -> None:
    p.add_argument("gripper_poses", type=Path, help="T_base_gripper list (CSV/YAML, scalar-last quaternions)")
    p.add_argument("target_poses", type=Path, help="T_cam_target list (CSV/YAML)")


def _handeye_calibrate(args) -> int:
    from robocal.rigs.lineprofiler.handeye import calibrate_hand_eye

    tick = _stages("handeye: read poses, solve", 2)
    tick()
    Tg, Tc = _load_pose_pair(args)
    tick()
    res = _solve_named(args, calibrate_hand_eye, Tg, Tc, args.method, refine=not args.no_refine,
                       accept_implausible=args.accept_implausible,
                       names=(Path(args.gripper_poses).name, Path(args.target_poses).name))
    std = {"T_gripper_cam.rotvec": [res.std.get(k) for k in ("rx", "ry", "rz")] if res.std else None,
           "T_gripper_cam.translation": [res.std.get(k) for k in ("tx", "ty", "tz")] if res.std else None}
    result = CalibrationResult(
        rig="handeye", method=res.method, estimate={"T_gripper_cam": res.X.tolist(), "T_base_target": res.Y.tolist()},
        std=std, units={"T_gripper_cam": "m", "T_base_target": "m", "T_gripper_cam.rotvec": "rad",
                        "T_gripper_cam.translation": "m"},
        residual_rms=res.trans_rms, residual_unit="m", warnings=res.warnings,
        inputs=hash_inputs([args.gripper_poses, args.target_poses]),
        diagnostics={"rotation_rms_rad": res.rot_rms, "n_motions": res.n_motions,
                     "convention": "A X = X B, X = T_gripper_cam, quaternions scalar-last"})
    rep = Report("handeye: AX = XB", subtitle=res.method)
    s = rep.section("Estimate")
    s.parameters({"T_gripper_cam": res.X, "rotation residual rms [rad]": res.rot_rms,
                  "translation residual rms [m]": res.trans_rms}, {})
    if res.std:
        s.parameters({k: 0.0 for k in res.std}, {k: v for k, v in res.std.items()})
    s.diagnostics(res.warnings)
    out = prepare_out_dir(args.out, "handeye")
    write_run(out, result, rep)
    st = [res.std.get(k) for k in ("tx", "ty", "tz")] if res.std else [None] * 3
    print(f"T_gripper_cam translation [mm] ({res.method}): " + ", ".join(
        f"{1e3 * v:.3f}" + ("" if s is None else f" +/- {1e3 * s:.3f}") for v, s in zip(res.X[:3, 3], st)))
    return 0


def _robot_world(args) -> int:
    from robocal.geometry import invert_transform
    from robocal.rigs.lineprofiler.handeye import calibrate_robot_world, invert_with_covariance

    tick = _stages("handeye robot-world: read poses, solve", 2)
    tick()
    Tg, Tc = _load_pose_pair(args)
    tick()
    # A X = Z B with A = T_cam_target, B = T_gripper_base: X = T_target_base, Z = T_cam_gripper
    res = _solve_named(args, calibrate_robot_world, Tc, invert_transform(Tg), refine=not args.no_refine,
                       accept_implausible=args.accept_implausible,
                       names=(Path(args.gripper_poses).name, Path(args.target_poses).name))

    def std_of(prefix):
        if not res.std:
            return None, None
        return ([res.std.get(f"{prefix}.{k}") for k in ("rx", "ry", "rz")],
                [res.std.get(f"{prefix}.{k}") for k in ("tx", "ty", "tz")])

    (xr, xt), (zr, zt) = std_of("X"), std_of("Z")
    # the inverses the user reads (T_gripper_cam, T_base_target): covariance through the inverse, first order
    inv_std = {}
    if res.cov is not None and res.std and all(res.std.get(f"{b}.{k}") is not None for b in "XZ"
                                               for k in ("rx", "ry", "rz", "tx", "ty", "tz")):
        for name, T, sl in (("T_base_target", res.X, slice(0, 6)), ("T_gripper_cam", res.Z, slice(6, 12))):
            _, C = invert_with_covariance(T, np.asarray(res.cov)[sl, sl])
            sd = np.sqrt(np.maximum(np.diag(C), 0.0))
            inv_std[f"{name}.rotvec"], inv_std[f"{name}.translation"] = sd[:3].tolist(), sd[3:].tolist()
    result = CalibrationResult(
        rig="handeye", method=f"robot-world {res.method}",
        estimate={"T_target_base": res.X.tolist(), "T_cam_gripper": res.Z.tolist(),
                  "T_base_target": invert_transform(res.X).tolist(),
                  "T_gripper_cam": invert_transform(res.Z).tolist()},
        std={"T_target_base.rotvec": xr, "T_target_base.translation": xt, "T_cam_gripper.rotvec": zr,
             "T_cam_gripper.translation": zt, **inv_std},
        units={k: "m" for k in ("T_target_base", "T_cam_gripper", "T_base_target", "T_gripper_cam",
                                "T_target_base.translation", "T_cam_gripper.translation",
                                "T_base_target.translation", "T_gripper_cam.translation")}
        | {"T_target_base.rotvec": "rad", "T_cam_gripper.rotvec": "rad", "T_base_target.rotvec": "rad",
           "T_gripper_cam.rotvec": "rad"},
        residual_rms=res.trans_rms, residual_unit="m", warnings=res.warnings,
        inputs=hash_inputs([args.gripper_poses, args.target_poses]),
        diagnostics={"rotation_rms_rad": res.rot_rms, "n_poses": len(Tc),
                     "convention": "A X = Z B, A = T_cam_target, B = T_gripper_base (inverse of the robot's "
                                   "T_base_gripper), X = T_target_base, Z = T_cam_gripper; std as rotation "
                                   "vector of R_perturbed R^T (rad) and translation (m); quaternions scalar-last"})
    rep = Report("handeye: robot-world AX = ZB", subtitle=res.method)
    s = rep.section("Estimate")
    s.parameters({"T_gripper_cam": invert_transform(res.Z), "T_base_target": invert_transform(res.X),
                  "rotation residual rms [rad]": res.rot_rms, "translation residual rms [m]": res.trans_rms}, {})
    if res.std:
        s.parameters({k: 0.0 for k in res.std}, dict(res.std))
    if inv_std:
        s.table([{"": k, "rx [mrad]": 1e3 * inv_std[f"{k}.rotvec"][0], "ry [mrad]": 1e3 * inv_std[f"{k}.rotvec"][1],
                  "rz [mrad]": 1e3 * inv_std[f"{k}.rotvec"][2], "tx [mm]": 1e3 * inv_std[f"{k}.translation"][0],
                  "ty [mm]": 1e3 * inv_std[f"{k}.translation"][1], "tz [mm]": 1e3 * inv_std[f"{k}.translation"][2]}
                 for k in ("T_gripper_cam", "T_base_target")], digits=3,
                caption="standard deviation of the inverses (first-order propagation through the inverse)")
    s.diagnostics(res.warnings)
    out = prepare_out_dir(args.out, "handeye-robot-world")
    write_run(out, result, rep)
    st = inv_std.get("T_gripper_cam.translation", [None] * 3)
    print("T_gripper_cam translation [mm]: " + ", ".join(
        f"{1e3 * v:.3f}" + ("" if sd is None else f" +/- {1e3 * sd:.3f}")
        for v, sd in zip(invert_transform(res.Z)[:3, 3], st)))
    sr = inv_std.get("T_gripper_cam.rotvec")
    if sr is not None:
        print("T_gripper_cam rotation std [mrad] (rotation vector of R_perturbed R^T): "
              + ", ".join(f"{1e3 * v:.3f}" for v in sr))
    return 0


def _add_handeye(parser) -> None:
    sub = parser.add_subparsers(dest="subcommand", metavar="COMMAND")
    p = sub.add_parser("calibrate", help="eye-in-hand X = T_gripper_cam from two pose lists",
                       formatter_class=RawHelp, epilog=examples_epilog(
                           f"robocal handeye calibrate {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                           "--method park --out he"))
    _pose_list_arguments(p)
    p.add_argument("--method", default="tsai", choices=["tsai", "park", "horaud", "andreff", "daniilidis"],
                   help="closed-form AX = XB solver (then refined unless --no-refine)")
    p.add_argument("--no-refine", action="store_true", help="closed form only (no covariance)")
    add_accept_implausible_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_handeye_calibrate)
    p = sub.add_parser("robot-world", help="A X = Z B: T_gripper_cam and T_base_target together (Shah + refinement)",
                       formatter_class=RawHelp, epilog=examples_epilog(
                           f"robocal handeye robot-world {EXAMPLES}/gripper_poses.csv {EXAMPLES}/target_poses.csv "
                           "--out rw"))
    _pose_list_arguments(p)
    p.add_argument("--no-refine", action="store_true", help="Shah's closed form only (no covariance)")
    add_accept_implausible_argument(p)
    add_out_argument(p)
    p.set_defaults(func=_robot_world)


HANDEYE = Rig(name="handeye", help="AX = XB hand-eye solvers (Tsai, Park, Horaud, Andreff, Daniilidis) and "
                                   "robot-world AX = ZB, with refinement",
              description="Classic hand-eye calibration from pose lists (see docs/rigs/lineprofiler.md).\n\n"
                          + examples_epilog(f"robocal handeye calibrate {EXAMPLES}/gripper_poses.csv "
                                            f"{EXAMPLES}/target_poses.csv --method park --out he",
                                            f"robocal handeye robot-world {EXAMPLES}/gripper_poses.csv "
                                            f"{EXAMPLES}/target_poses.csv --out rw"),
              add_commands=_add_handeye)
