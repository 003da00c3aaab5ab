"""The hand-eye report (``robocal handeye calibrate | robot-world | report``), built from the result alone."""

from __future__ import annotations

import numpy as np

__all__ = ["build_report"]


def build_report(result, *, base_dir=None):
    """The hand-eye report from the result alone: poses, per-pose closure residuals, the closed forms
    compared, the solver record."""
    from robocal.report import Report, new_figure, solver_section

    rw = result.method.startswith("robot-world")
    rep = Report("handeye: robot-world AX = ZB" if rw else "handeye: AX = XB", subtitle=result.method)
    d = result.diagnostics
    s = rep.section("Estimate")
    s.parameters(result.estimate, result.std, result.units)
    s.table([{"quantity": "rotation residual RMS [mrad]", "value": 1e3 * (d.get("rotation_rms_rad") or np.nan)},
             {"quantity": "translation residual RMS [mm]", "value": 1e3 * (result.residual_rms or np.nan)}],
            ["quantity", "value"], digits=4)
    s.text(d.get("convention", ""))
    s.diagnostics(result.warnings)
    if d.get("recording") or d.get("views"):  # where the poses came from (a recording; images)
        from robocal.handeye.bag_input import report_section

        report_section(rep, d)
    cl = d.get("closure_residuals")
    if cl:
        fig, ax = new_figure(1, 2, size=(10, 3.2))
        n = np.arange(len(cl["rotation_rad"]))
        for a, key, label in ((ax[0], "rotation_rad", "rotation residual [mrad]"),
                              (ax[1], "translation_m", "translation residual [mm]")):
            v = 1e3 * np.asarray(cl[key], float)
            if len(n) <= 200:
                a.bar(n, v)
            else:                               # 10^4 bars take seconds to draw and show nothing more
                a.plot(n, v, ".", ms=2)
            a.set_xlabel("pose")
            a.set_ylabel(label)
        rep.section("Residuals").figure(fig, "closure residual per pose: " + d.get(
            "closure", "T_base_gripper[i] X T_cam_target[i] = Y") + " (Y: the target's pose)")
    cmp = d.get("solver_comparison")
    if cmp:
        rows = [{"closed form": c["method"],
                 "rotation vs estimate [mrad]": None if "error" in c else 1e3 * c["rotation_diff_rad"],
                 "translation vs estimate [mm]": None if "error" in c else 1e3 * c["translation_diff_m"],
                 "rotation RMS [mrad]": None if "error" in c else 1e3 * c["rotation_rms_rad"],
                 "translation RMS [mm]": None if "error" in c else 1e3 * c["translation_rms_m"],
                 **({"failed": c["error"]} if any("error" in e for e in cmp) else {})} for c in cmp]
        pairs = next((c["pairs"] for c in cmp if "pairs" in c), "all")
        nm = next((c["n_motions"] for c in cmp if "n_motions" in c), None)
        which = {"all": "the relative motions of all pose pairs",
                 "consecutive": "the motions between consecutive poses",
                 "auto": "the estimate's motions (--pairs auto: all pairs up to 200 poses, else consecutive "
                         "ones and well-conditioned longer ones)"}.get(pairs, pairs)
        rep.section("Closed-form solvers compared").table(
            rows, digits=4, caption="each closed form against the estimate above, on " + which
            + ("" if nm is None else f" ({nm} motions)"))
    st = d.get("streams")
    if st:
        rows = [{"stream": k, "stamps not advancing (dropped)": st["dropped_stamps"].get(k, 0),
                 "outside the other's span": st["cropped"].get(k, 0)} for k in ("robot", "camera")]
        rep.section("Streams and clocks").table(
            rows, caption=f"{st['n_pairs']} pairs by time; camera samples outside the robot stream are cropped, robot "
            f"samples before the first / after the last camera sample unused. Clock offset ({st['mode']}): "
            f"{1e3 * st['clock_offset_s']:.3f} ms" + ("" if st.get("correlation") is None else
                                                       f", rotation-rate correlation {st['correlation']:.3f}")
            + (". " + st["clock_offset_meaning"] if st.get("clock_offset_meaning") else ""))
    jk = d.get("jackknife")
    if jk:
        comp = ("rx [mrad]", "ry [mrad]", "rz [mrad]", "tx [mm]", "ty [mm]", "tz [mm]")
        rows = [{"component": c, "first-order std": None if f is None else 1e3 * f, "jackknife std": 1e3 * j,
                 "jackknife / first-order": None if not f else j / f}
                for c, f, j in zip(comp, jk["first_order_std"], jk["std"])]
        rep.section("Jackknife").table(
            rows, digits=4, caption=f"{jk['pose']}: {jk['kind']} jackknife over {jk['replicates']} replicates "
            f"({jk['poses_per_replicate']} pose(s) left out each) beside the refinement's first-order std; a ratio "
            "far from 1 says the residuals are not the independent, alike noise the first-order std assumes "
            "(a few poses carry the error or the information)")
    solver_section(rep.section("Solver (refinement)"), d.get("solver") or {})
    return rep
