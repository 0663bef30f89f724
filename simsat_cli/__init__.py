"""The ``simsat`` command line: the application shell at the top of the stack.

It sits above the three packages it chains — ``simsat`` (scenario, render,
product), ``restore`` and ``reports`` — none of which imports it. Importing
``restore`` registers the ``[restoration]`` table in the scenario's single
validation pass (:mod:`simsat.validation`). ``reports`` (matplotlib, PyVista)
is imported by the commands that draw, to keep ``simsat validate`` and
``simsat --help`` fast.
"""
from __future__ import annotations

import argparse
import errno
import os
import re
import subprocess
import sys
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10: the backport the package declares
    import tomli as tomllib

import restore.settings  # noqa: F401  (registers [restoration] in the validation pass)
from restore.pipeline import restore_run
from simsat import __version__
from simsat.config import ScenarioError
from simsat.product import ProductError, atomic_write_json
from simsat.rundir import REPORT_MANIFEST, RunLock, check_consistency, prepare_output_dir, read_ids
from simsat.scenario import builtin_scenarios, load_scenario
from simsat.simulate import simulate

__all__ = ["main"]


class CliError(Exception):
    """An error to print as one line (no traceback)."""


def _print_err(msg: str) -> None:
    print(f"simsat: error: {msg}", file=sys.stderr)


def _parse_set(items: list[str] | None) -> dict:
    """``--set key.sub=value`` overrides (value parsed as TOML)."""
    out: dict = {}
    for item in items or []:
        if "=" not in item:
            raise CliError(f"--set {item!r}: expected KEY=VALUE (e.g. acquisition.lines=512)")
        key, value = item.split("=", 1)
        try:
            parsed = tomllib.loads(f"v = {value}")["v"]
        except Exception:
            parsed = value
        path: list = []
        for part in key.strip().split("."):
            m = re.fullmatch(r"([A-Za-z0-9_-]+)((?:\[\d+\])*)", part)
            if not m:
                raise CliError(f"--set {item!r}: {part!r} is not a key name (KEY or KEY[INDEX], e.g. "
                               f"attitude.jitter[0].amplitude_urad=2.0)")
            path.append(m.group(1))
            path.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
        d = out
        for p in path[:-1]:
            d = d.setdefault(p, {})
        d[path[-1]] = parsed
    return out


# --------------------------------------------------------------------------- commands
def cmd_scenarios(args) -> int:
    width = max(len(n) for n in builtin_scenarios())
    for name, path in builtin_scenarios().items():
        try:
            sc = load_scenario(path, check_models=False)
            d = sc.instrument.detectors
            size = (f"{sc.acquisition.lines} frames of {d[0].rows} x {d[0].pixels} px" if sc.acquisition.is_frames
                    else f"{sc.acquisition.lines} lines x {d[0].pixels} px x {len(d)} bands")
            print(f"{name:{width}s}  {size:32s} {sc.description}")
        except Exception as e:  # pragma: no cover - a broken built-in is a bug
            print(f"{name:{width}s}  (invalid: {e})")
    print(f"\n(files in {next(iter(builtin_scenarios().values())).parent})")
    from navigation.scenario import builtin_navigation_scenarios, load_navigation_scenario

    print("\nnavigation scenarios (simsat navigate):")
    for name, path in builtin_navigation_scenarios().items():
        sc = load_navigation_scenario(path)
        print(f"{name:14s} {sc.length_m / 1000:.0f} km, {sc.camera.width} x {sc.camera.height} {sc.sensor.band} camera, "
              f"{sc.imu.gyro_bias_deg_h:g} °/h / {sc.imu.accel_bias_mg:g} mg IMU, {sc.seeds} seeds"
              + (f", degraded: {', '.join(d.kind for d in sc.degraded)}" if sc.degraded else ""))
    return 0


def cmd_validate(args) -> int:

    sc = load_scenario(args.scenario, overrides=_parse_set(args.set))  # every table, every stage
    d = sc.instrument.detectors
    size = (f"{sc.acquisition.lines} frames of {d[0].rows} x {d[0].pixels} px" if sc.acquisition.is_frames
            else f"{sc.acquisition.lines} lines x {d[0].pixels} px")
    print(f"{sc.source or args.scenario}: OK — {sc.name}: {size}, "
          f"{len(d)} bands ({', '.join(x.name for x in d)}), scene x ∈ [{sc.x_range_m[0]:.0f}, {sc.x_range_m[1]:.0f}] m")
    return 0


def cmd_render(args) -> int:

    sc = load_scenario(args.scenario, overrides=_parse_set(args.set))
    out = Path(args.out) if args.out else Path("runs") / sc.name
    res = simulate(sc, out, progress=not args.quiet, force=args.force)
    _say_replaced(out, res.replaced)
    rs = res.render_stats
    print(f"wrote {out}/product.nc, truth.nc, run.json — {rs['rays']:,} rays in {rs['wall_s']:.1f} s "
          f"({rs['rays_per_s'] / 1e6:.2f} Mrays/s, {rs['variant']}); total {res.timings['total_s']:.1f} s")
    return 0


def _say_replaced(out: Path, replaced: list) -> None:
    if replaced:
        print(f"{out}: replaced simsat's earlier outputs ({', '.join(replaced)}); nothing else was touched",
              file=sys.stderr)


def _report(run_dir: Path, out_dir, *, quiet: bool) -> Path:
    """Write the report of a run while holding its lock; refuse a run of mixed files."""
    from reports.run_report import make_run_report  # matplotlib, PyVista: heavy


    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        what = "is a file" if run_dir.exists() else "does not exist"
        raise ProductError(f"{run_dir}: {what}; expected a run directory (made by `simsat render` or `simsat run`)")
    if not (run_dir / "product.nc").exists():
        raise ProductError(f"{run_dir / 'product.nc'}: file not found; {run_dir} is not a run directory "
                           f"(run `simsat render SCENARIO --out {run_dir}` first)")
    check_consistency(run_dir)
    with RunLock(run_dir, "report"):
        t0 = time.time_ns()
        path = make_run_report(run_dir, out_dir=out_dir, progress=not quiet)
        _write_report_manifest(Path(path).parent, since_ns=t0, run_dir=run_dir)
        return path


def _write_report_manifest(report_dir: Path, *, since_ns: int, run_dir: Path) -> None:
    """List the files this report wrote (so a later render removes exactly those, and nothing of the user's)."""

    files = sorted(e.name for e in os.scandir(report_dir)
                   if e.is_file(follow_symlinks=False) and not e.name.startswith(".")
                   and e.stat().st_mtime_ns >= since_ns - 2_000_000_000)
    atomic_write_json({"files": files, **read_ids(run_dir / "restoration.nc"),
                       "product_id": read_ids(run_dir / "product.nc").get("product_id")},
                      report_dir / REPORT_MANIFEST)


def _summary(run_dir: Path, report_path=None) -> str:
    from reports.summary import run_summary  # matplotlib (via reports): heavy

    return run_summary(run_dir, report_path=report_path)


def cmd_restore(args) -> int:

    res = restore_run(args.run_dir, overrides=_parse_set(args.set), progress=not args.quiet)
    if not args.quiet:
        print(res.summary())
    if not args.no_summary:
        print(_summary(Path(args.run_dir)))
    return 0


def cmd_report(args) -> int:
    path = _report(Path(args.run_dir), args.out, quiet=args.quiet)
    print(f"wrote {path}")
    return 0


def cmd_run(args) -> int:
    """Render, restore and report, each stage in its own process.

    The stages hand over through the run directory's files anyway; a fresh
    process per stage gives each its own memory, so the peak of the whole run
    is that of its largest stage, not their sum of leftovers.
    """

    sc = load_scenario(args.scenario, overrides=_parse_set(args.set))
    out = Path(args.out) if args.out else Path("runs") / sc.name
    sets = [x for item in (args.set or []) for x in ("--set", item)]
    quiet = ["--quiet"] if args.quiet else []
    stages = [["render", str(args.scenario), "--out", str(out), *sets, *quiet, *(["--force"] if args.force else [])],
              ["restore", str(out), "--no-summary", *quiet],
              ["report", str(out), *quiet]]
    for argv in stages:
        rc = subprocess.run([sys.executable, "-m", "simsat_cli", *argv]).returncode
        if rc != 0:
            return rc
    print(_summary(out, report_path=out / "report" / "index.html"))
    return 0


def cmd_figures(args) -> int:
    from reports.figures import make_patent_figures  # matplotlib: heavy

    paths = make_patent_figures(Path(args.out), monte_carlo=not args.no_monte_carlo, seed=args.seed,
                                progress=not args.quiet)
    for p in paths:
        print(p)
    return 0


def cmd_bench(args) -> int:
    if args.what == "compare":
        from reports import history

        try:
            records = history.read_history(args.history)
        except history.HistoryError as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        prev, latest, changes = history.compare(records, benchmark=args.benchmark)
        print(history.format_comparison(prev, latest, changes))
        return 1 if any(c.regression for c in changes) else 0
    from reports import bench  # matplotlib, Mitsuba: heavy

    overrides = _parse_set(args.set)
    if overrides and args.what not in bench.OVERRIDABLE:
        raise CliError(f"--set: only `simsat bench {' / '.join(bench.OVERRIDABLE)}` take scenario overrides")
    result = bench.run_bench(args.what, scenario=args.scenario, out=args.out,
                             lines=args.seeds if args.what in ("navigation", "knowledge") else args.lines,
                             seed=args.seed,
                             history=args.history, overrides=overrides)
    print(bench.format_result(args.what, result))
    print(f"\nwrote {result['_path']}; appended to the accuracy history {result['_history']} "
          f"(`simsat bench compare` sets it against the previous run)")
    if args.what == "regression" and result["result"]["passed"] < result["result"]["total"]:
        return 1
    return 0


def cmd_navigate(args) -> int:
    from navigation.io import read_navigation, summarise, write_navigation
    from navigation.run import NavigationRun
    from navigation.scenario import load_navigation_scenario

    sc = load_navigation_scenario(args.scenario, overrides=_parse_set(args.set))
    out = Path(args.out) if args.out else Path("runs") / sc.name
    prepare_output_dir(out, force=args.force)
    seeds = list(range(args.seeds)) if args.seeds else None
    with RunLock(out, "navigate"):
        res = NavigationRun(sc, progress=not args.quiet).run(seeds=seeds, scheduler=args.scheduler,
                                                             workers=args.workers)
        write_navigation(res, out)
        report = None
        if not args.no_report:
            from reports.navigation_report import make_navigation_report

            report = make_navigation_report(out)
    s = summarise(read_navigation(out))
    f = s["final_horizontal_m"]
    print(f"wrote {out}/navigation.nc" + (f" and {report}" if report else ""))
    print(f"{sc.name}: {s['seeds']} seeds over {s['distance_km']:.0f} km — final horizontal error median "
          f"{f['median']:.1f} m, p95 {f['p95']:.1f} m (unaided median {s['unaided_final_horizontal_m']['median']:.0f} m,"
          f" {s['improvement_median']:.0f}× better); fixes on {100 * s['fixes_fraction']:.0f} % of updates; "
          f"NEES inside the χ²₃ 95 % interval on {100 * s['nees_inside_fraction']:.0f} % of (seed, update)")
    return 0


def cmd_study(args) -> int:
    from reports.study.runner import run_study
    from reports.study.spec import load_study

    spec = load_study(args.study)
    out = Path(args.out) if args.out else Path("studies") / "out" / spec.name
    n = len(spec.points())
    where = args.scheduler or f"a local cluster of {args.workers or os.cpu_count()} worker processes"
    if not args.quiet:
        print(f"study {spec.name}: {len(spec.designs())} designs × {len(spec.seeds)} seeds = {n} points "
              f"({spec.level} level) on {where} → {out}", file=sys.stderr)
    res = run_study(spec, out, scheduler=args.scheduler, workers=args.workers, progress=not args.quiet)
    failed = [r for r in res["rows"] if r.get("error")]
    print(f"study {spec.name}: {len(res['rows'])} of {res['total']} points in the table ({res['computed']} computed "
          f"now, {len(failed)} failed)")
    for k, p in res["paths"].items():
        print(f"  {k}: {p}")
    return 1 if failed else 0


def cmd_optimise(args) -> int:
    from reports.optimise import optimise_layout
    from reports.study.evaluate import calibrate_noise
    from simsat.scenario import load_scenario

    sc = load_scenario(args.scenario)
    out = Path(args.out) if args.out else Path("runs") / f"optimise_{sc.name}"
    noise = args.noise_px
    if noise is None:
        print(f"optimise: calibrating the matching noise on a rendered run of {sc.name} ...", file=sys.stderr)
        noise = calibrate_noise(args.scenario, {}, out / "calibration_run")["noise_px"]
    res = optimise_layout(args.scenario, out, noise_px=noise, seeds=tuple(range(args.seeds)),
                          max_spread_s=None if args.max_spread_ms is None else args.max_spread_ms * 1e-3,
                          confirm=not args.no_confirm, progress=not args.quiet)
    for tag in ("reference", "best"):
        r = res[tag]
        line = (f"{tag:9s} τ = {' / '.join(f'{x:.1f}' for x in r['tau_ms'])} ms: predicted roll "
                f"{r['predicted_px']['roll']:.4f}, pitch {r['predicted_px']['pitch']:.4f} px")
        if "rendered_px" in r:
            line += (f"; rendered {r['rendered_px']['roll']:.4f} / {r['rendered_px']['pitch']:.4f} px (× "
                     f"{r['rendered_over_predicted']['roll']:.2f} / {r['rendered_over_predicted']['pitch']:.2f})")
        print(line)
    for p in res["_paths"]:
        print(f"  wrote {p}")
    return 0


# --------------------------------------------------------------------------- parser
def _add_study_and_bench(sub, quiet_help: str) -> None:
    """The parsers of ``study``, ``optimise`` and ``bench``."""
    s = sub.add_parser("study", help="a trade study: sweeps and Monte Carlo over scenario keys, on Dask (resumable)")
    s.add_argument("study", help="STUDY.toml (see reports/study/spec.py and studies/*.toml)")
    s.add_argument("--out", default=None, help="output directory (default studies/out/<name>); a study started "
                                              "again there computes only the missing points")
    s.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                   help="run on an existing Dask scheduler (default: a local cluster on this machine's cores)")
    s.add_argument("--workers", type=int, default=None, help="local cluster: worker processes (default: cores)")
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_study)

    s = sub.add_parser("optimise", help="the three-band layout (τ set) that minimises the predicted restored error")
    s.add_argument("--scenario", default="phr_cmg", help="the jitter spectrum, geometry and reference layout "
                                                         "(default: %(default)s)")
    s.add_argument("--noise-px", type=float, default=None,
                   help="matching noise per line and pair [px] (default: calibrated on a rendered run)")
    s.add_argument("--max-spread-ms", type=float, default=None,
                   help="largest delay between the first and the last band [ms] (default: the focal-plane height)")
    s.add_argument("--seeds", type=int, default=5, help="Monte Carlo seeds of the prediction (default: %(default)s)")
    s.add_argument("--no-confirm", action="store_true", help="do not render the best and the reference layouts")
    s.add_argument("--out", default=None, help="output directory (default runs/optimise_<scenario>)")
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_optimise)

    s = sub.add_parser("navigate", help="the forward-camera INS aiding system: render the flight, run the Monte "
                                        "Carlo of aided and unaided INS, write navigation.nc and its report")
    s.add_argument("scenario", help="navigation scenario: a built-in name (nav_default, nav_degraded, nav_tiny) "
                                    "or a .toml path")
    s.add_argument("--out", default=None, help="run directory (default runs/<name>)")
    s.add_argument("--seeds", type=int, default=None, help="number of Monte Carlo seeds (default: navigation.seeds)")
    s.add_argument("--workers", type=int, default=None, help="local Dask worker processes (default: cores; 1: "
                                                             "in this process)")
    s.add_argument("--scheduler", default=None, help="run the seeds on an existing Dask scheduler (tcp://HOST:PORT)")
    s.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a scenario key")
    s.add_argument("--no-report", action="store_true", help="skip the HTML report")
    s.add_argument("--force", action="store_true", help="write into a non-empty directory that is not a run")
    s.add_argument("--quiet", action="store_true", help="no progress bars")
    s.set_defaults(func=cmd_navigate)

    s = sub.add_parser("bench", help="benchmarks (results printed and written as JSON)")
    s.add_argument("what", choices=["render", "restore", "matching", "integration", "knowledge", "memory",
                                    "robustness", "regression", "navigation", "compare"],
                   help="what to measure (knowledge: a causal AOCS knowledge's record ends, dephased and advanced, "
                        "against the attitude through |F|, over 30 draws of six stress attitudes at 2 / 4 / 8 Hz, "
                        "no rendering; memory: peak RSS of render, restore and report at 4 000, 16 000 and "
                        "50 000 lines, each in its own process; regression: every built-in and stress scenario "
                        "against its own requirement, exit 1 if one fails); compare: the last bench record "
                        "against the previous one with the same settings, exit 1 on a regression")
    s.add_argument("--scenario", default=None, help="scenario (render/restore; default phr_cmg)")
    s.add_argument("--lines", type=int, default=None, help="override acquisition.lines (memory: measure this length only)")
    s.add_argument("--seed", type=int, default=0, help="scenario seed of the bench runs (default: %(default)s)")
    s.add_argument("--out", default=None, help="JSON output file (default bench/<what>.json)")
    s.add_argument("--history", default="bench/history.jsonl",
                   help="accuracy history every bench appends to, and compare reads (default: %(default)s)")
    s.add_argument("--benchmark", default=None, help="compare: which benchmark's records (default: the last run)")
    s.add_argument("--seeds", type=int, default=None,
                   help="navigation: Monte Carlo seeds (default: the scenario's); knowledge: draws per row (default 30)")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="robustness / regression: override a key of every scenario, e.g. "
                        "--set restoration.noise_colour_weighting=false (value in TOML syntax; the runs go to their "
                        "own scratch directories and the JSON to bench/<what>_set.json unless --out says)")
    s.set_defaults(func=cmd_bench)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simsat", description="Push-broom LOS jitter simulator and restoration testbed")
    p.add_argument("--version", action="version", version=f"simsat {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("scenarios", help="list the built-in scenarios")
    s.set_defaults(func=cmd_scenarios)

    s = sub.add_parser("validate", help="check a scenario file without rendering")
    s.add_argument("scenario", help="scenario: a TOML file path (must exist), or the name of a built-in scenario")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set acquisition.lines=512 (value in TOML syntax)")
    s.set_defaults(func=cmd_validate)

    scen_help = ("scenario: a TOML file path (must exist), or the name of a built-in scenario "
                 "(`simsat scenarios` lists them; e.g. phr_cmg)")
    set_help = ("override a scenario key, e.g. --set acquisition.lines=512 (value in TOML syntax; "
                "repeat for several keys)")
    out_help = ("run directory to write (default runs/<scenario name>); a new or empty directory, or a "
                "simsat run whose simsat files are replaced; another non-empty directory needs --force")
    force_help = ("write into a non-empty directory that is not a simsat run: simsat's files are written "
                  "beside the others, nothing else is touched")
    quiet_help = "no progress bars or stage messages (the result lines are still printed)"
    run_dir_help = "run directory written by `simsat render` or `simsat run` (holds product.nc)"

    s = sub.add_parser("render", help="render a scenario into a product (product.nc, truth.nc, run.json)")
    s.add_argument("scenario", help=scen_help)
    s.add_argument("--out", help=out_help)
    s.add_argument("--force", action="store_true", help=force_help)
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help=set_help)
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_render)

    s = sub.add_parser("restore", help="restore the LOS attitude of a rendered product (writes restoration.nc)")
    s.add_argument("run_dir", help=run_dir_help)
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a [restoration] key, e.g. --set method=wiener or --set integration.k=1e-3")
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.add_argument("--no-summary", action="store_true", help=argparse.SUPPRESS)  # used by `simsat run`
    s.set_defaults(func=cmd_restore)

    s = sub.add_parser("report", help="write the HTML report of a run")
    s.add_argument("run_dir", help=run_dir_help)
    s.add_argument("--out", help="report directory (default RUN_DIR/report)")
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_report)

    s = sub.add_parser("run", help="render → restore → report in one go, then print the restored error")
    s.add_argument("scenario", help=scen_help)
    s.add_argument("--out", help=out_help)
    s.add_argument("--force", action="store_true", help=force_help)
    s.add_argument("--set", action="append", metavar="KEY=VALUE", help=set_help)
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("figures", help="the founding patent's figures 7–14 (PNG + CSV)")
    s.add_argument("--out", default="figures", help="directory for the PNG and CSV files (default: %(default)s)")
    s.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo points (default: %(default)s)")
    s.add_argument("--no-monte-carlo", action="store_true", help="analytic curves only")
    s.add_argument("--quiet", action="store_true", help=quiet_help)
    s.set_defaults(func=cmd_figures)

    _add_study_and_bench(sub, quiet_help)
    return p


def _os_hint(e: OSError) -> str:

    hints = {errno.EEXIST: " (a file is in the way where a directory is needed)",
             errno.ENOTDIR: " (a path component is a file, not a directory)",
             errno.EACCES: " (no permission: choose a writable location)",
             errno.EPERM: " (no permission: choose a writable location)",
             errno.EROFS: " (read-only file system: choose a writable location)",
             errno.ENOSPC: " (disk full: free space or write elsewhere)",
             errno.EISDIR: " (a directory is in the way of a file)"}
    return hints.get(e.errno, "")


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2

    try:
        return int(args.func(args) or 0)
    except (ScenarioError, ProductError, CliError) as e:
        _print_err(str(e))
        return 2
    except FileNotFoundError as e:
        _print_err(f"{e.filename}: file not found" if e.filename else str(e))
        return 2
    except MemoryError:
        _print_err("out of memory; reduce the scenario's size (acquisition.lines, instrument pixels) or "
                   "acquisition.block_lines")
        return 2
    except OSError as e:
        # the environment refused a file operation (a file in the way of a directory, no permission,
        # disk full, read-only file system): a user-fixable condition that names its path
        if e.filename is not None or e.errno is not None:
            where = f"{e.filename}: " if e.filename is not None else ""
            other = f" -> {e.filename2}" if getattr(e, "filename2", None) else ""
            _print_err(f"{where}{e.strerror or e}{other}" + _os_hint(e))
            return 2
        if os.environ.get("SIMSAT_DEBUG"):
            raise
        _print_err(f"internal error ({type(e).__name__}: {e}); set SIMSAT_DEBUG=1 for the traceback")
        return 1
    except KeyboardInterrupt:
        _print_err("interrupted")
        return 130
    except Exception as e:
        # library-level validation errors (ValueError naming the field) and
        # restoration failures are user-facing; anything else is a bug.
        from_restore = type(e).__module__.split(".")[0] in ("restore", "reports")
        if isinstance(e, ValueError) or from_restore:
            _print_err(str(e).splitlines()[0] if str(e) else type(e).__name__)
            return 2
        if os.environ.get("SIMSAT_DEBUG"):
            raise
        _print_err(f"internal error ({type(e).__name__}: {e}); set SIMSAT_DEBUG=1 for the traceback")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
