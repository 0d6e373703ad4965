"""The command line's arguments: the option groups several commands share and the
parser (:func:`build_parser`).

Every option with a value has a checked type (:mod:`pneubayes.cli.values`), so a bad
value is a usage error before any work starts; :func:`check_single_values` closes
argparse's one gap (``--opt=--``).
"""

from __future__ import annotations

import argparse

from pneubayes.cli.values import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    accepted_rules,
    assignment,
    bound,
    floats,
    parameter_names,
    pressure_filter,
    rig_card,
    setting,
    share,
)


def _add_limits(p) -> None:
    """--max-file-mb, on every command reading files (:mod:`pneubayes.limits`)."""
    p.add_argument("--max-file-mb", type=POSITIVE, default=None, metavar="MB",
                   help="largest input file read, MB (default 64, or the environment's "
                        "PNEUBAYES_MAX_FILE_MB; reading a recording takes about 20 x its "
                        "size in memory); only regular files are read (no pipes, devices "
                        "or folders)")


def _add_accept(p) -> None:
    _add_limits(p)
    p.add_argument("--rig", type=rig_card, default=None, metavar="CARD",
                   help="a rig card (pneubayes-rig/1, .json or .toml) describing the rig of "
                        "every recording (instead of the one a sidecar's 'rig' key names)")
    p.add_argument("--accept", type=accepted_rules, default=(), metavar="RULE[,RULE]",
                   help="accept these plausibility rules for every recording (an unusual "
                        "but real rig, e.g. sample-interval,pressure-span); a recording's "
                        "JSON can list them in accept_unusual")


class _Retired(argparse.Action):
    """An option that was removed: using it is a usage error saying what replaces it.
    Hidden from ``--help``; it takes an optional value so that ``--opt VALUE`` and
    ``--opt=VALUE`` both reach the message."""

    def __init__(self, option_strings, dest, replacement: str = "", **kwargs):
        super().__init__(option_strings, argparse.SUPPRESS, nargs="?",
                         default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        self.replacement = replacement

    def __call__(self, parser, namespace, values, option_string=None):
        parser.error(f"{option_string} {self.replacement}")


RESUME_RETIRED = ("is gone: the same command resumes the run in --out on its own; "
                  "'pneubayes resume RUN' insists on a resume (an error when there is "
                  "nothing to resume)")


def _add_run_folder(p) -> None:
    p.add_argument("--overwrite", action="store_true",
                   help="replace the run already in --out (its files only; yours stay)")
    p.add_argument("--resume", action=_Retired, replacement=RESUME_RETIRED)
    p.set_defaults(resume=False)  # True under 'pneubayes resume RUN'


def _add_settings_file(p, tree: str) -> None:
    p.add_argument("--settings", default=None, metavar="FILE.toml",
                   help=f"the settings tree ({tree}) as a TOML file, the same tables a "
                        "study's [settings] uses; the options below override it")


def _add_fit_settings(p) -> None:
    """fit's options that set its FitSettings (None: the settings file's, else the
    default)."""
    _add_settings_file(p, "FitSettings: horizon_s, stride_s, [sampler], ...")
    p.add_argument("--walkers", type=NON_NEGATIVE_INT, default=None,
                   help="sampler.n_walkers: emcee walkers (0: automatic)")
    p.add_argument("--max-steps", type=POSITIVE_INT, default=None,
                   help="sampler.max_steps: emcee step limit (20000)")
    p.add_argument("--seed", type=NON_NEGATIVE_INT, default=None,
                   help="sampler.seed (0; recorded)")
    _add_cutoffs(p)
    _add_windows(p)
    p.add_argument("--jacobian-refresh", type=POSITIVE_INT, default=None, metavar="K",
                   help="refine_jacobian_refresh: the refinement's finite-difference "
                        "Jacobian at every K-th accepted point, Broyden's update between (4)")
    p.add_argument("--no-dense-output", action="store_true",
                   help="sample_solver = SolverConfig.standard(): the posterior's "
                        "likelihood stops the integrator at every sample instead of "
                        "crossing the samples where the command holds")
    _add_bounds(p)


def _add_run_options(p) -> None:
    """The run folder, sized work, output and plausibility options of fit and discover."""
    _add_run_folder(p)
    p.add_argument("--force", action="store_true",
                   help="start work sized over its limit (over 20,000 prediction windows "
                        "or 1e7 window samples together, an emcee chain over 4 GB on "
                        "disk); without it such a run is refused before any work, saying "
                        "what it would cost")
    p.add_argument("--no-figures", action="store_true",
                   help="write no figures/ (saves the plotting time)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    _add_accept(p)


def _add_bounds(p) -> None:
    p.add_argument("--bounds", action="append", type=bound, default=[],
                   metavar="NAME=LOWER:UPPER",
                   help="replace a parameter's bounds, in its unit (a rig unlike the "
                        "paper's: e.g. dead_volume_m3=1e-5:5e-3 for a 1-L chamber); "
                        "repeatable; recorded in the model card")


def _add_horizon(p) -> None:
    p.add_argument("--horizon", type=POSITIVE, default=None, metavar="S",
                   help="horizon_s (and stride_s unless given): length of the open-loop "
                        "prediction windows the model is fitted and judged on, s (2, the "
                        "paper's; shorter for short triggered trials)")


def _add_windows(p) -> None:
    _add_horizon(p)
    p.add_argument("--stride", type=POSITIVE, default=None, metavar="S",
                   help="stride_s: spacing of the windows, s (default: the horizon, no "
                        "overlap)")


def _add_cutoffs(p) -> None:
    p.add_argument("--position-cutoff", type=NON_NEGATIVE, default=None, metavar="HZ",
                   help="position_cutoff_Hz: zero-phase low-pass of the measured position "
                        "before it drives the model, Hz; 0: raw (50)")
    p.add_argument("--supply-cutoff", type=NON_NEGATIVE, default=None, metavar="HZ",
                   help="supply_cutoff_Hz: the same for the measured supply (its sensor "
                        "noise biases the supply gain); 0: raw (100)")
    _add_pressure_filter(p)


def _add_pressure_filter(p) -> None:
    p.add_argument("--pressure-filter", type=pressure_filter, default=None,
                   metavar="ORDER:HZ",
                   help="pressure_filter: the pressure channel's zero-phase "
                        "(delay-compensated) Butterworth anti-alias filter, e.g. 2:1000 "
                        "for the virtual bench's DAQ; the model then predicts the reading "
                        "(default: none declared; a cutoff over 10 x the sample rate is "
                        "refused as a slip)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pneubayes",
        description="Thin-port pneumatic actuator models: simulate, check recordings, run "
                    "the virtual test bench.")
    from pneubayes import __version__

    p.add_argument("--version", action="version", version=f"pneubayes {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser("check", help="validate recordings against docs/recording-format.md",
                       description="Validate recordings (CSV + JSON pairs, "
                                   "docs/recording-format.md): print every problem with "
                                   "file, row or key, and reason (exit 1 if any), the "
                                   "plausibility warnings and the unit conversions.")
    c.add_argument("files", nargs="+", help="recording .csv/.json paths or stems")
    c.add_argument("-q", "--quiet", action="store_true",
                   help="print only problems and plausibility warnings")
    _add_accept(c)

    b = sub.add_parser(
        "bench", help="generate recordings on the virtual test bench",
        description="Simulate a rig with planted effects on a fine grid, pass it through a "
                    "sensor chain (anti-alias low-pass, sampling, noise) and write "
                    "recordings plus DIR/truth.json with every true parameter.")
    b.add_argument("--cylinder", required=True, help="AIR37, AIR200, SMC or PRN (Table I)")
    b.add_argument("--valve", required=True, help="valve1 or valve2 (Table II)")
    b.add_argument("--effects", default="", help="comma-separated effects to plant, e.g. "
                   "tube_delay,spool_lag (catalogue: cylinder_leak, tube_delay, "
                   "valve_deadzone, supply_fluctuation, heat_transfer, spool_lag, sensor_lag, "
                   "sensor_calibration, sensor_drift, sensor_nonlinearity, valve_stiction)")
    b.add_argument("--leak-form", default=None, choices=("orifice", "laminar"),
                   help="law of a planted cylinder_leak (default orifice, the paper's)")
    b.add_argument("--set", action="append", type=setting, metavar="NAME=VALUE",
                   help="override a true parameter, e.g. --set tube_delay_s=0.005")
    b.add_argument("--protocol", default="fixed", choices=("fixed", "moving"),
                   help="fixed: random steps at fixed positions; moving: aggressive piston "
                        "motion")
    b.add_argument("--duration", type=POSITIVE, default=20.0, help="seconds per recording")
    b.add_argument("--seed", type=NON_NEGATIVE_INT, required=True,
                   help="random seed (recorded in truth)")
    b.add_argument("--ranges", type=lambda s: floats(s, "--ranges"), default=None,
                   help="fixed protocol: command ranges in V (default 5,3,0.5)")
    b.add_argument("--positions", type=lambda s: floats(s, "--positions"),
                   default=None,
                   help="fixed protocol: positions as fractions of stroke (default 0.1,0.5,0.9)")
    b.add_argument("--count", type=POSITIVE_INT, default=None,
                   help="moving protocol: recordings (default 2)")
    b.add_argument("--rate", type=POSITIVE, default=1000.0, help="output sample rate, Hz")
    b.add_argument("--fine-rate", type=POSITIVE, default=10_000.0,
                   help="truth simulation grid, Hz (a multiple of --rate)")
    b.add_argument("--pressure-noise", type=NON_NEGATIVE, default=500.0,
                   help="pressure sensor noise std, Pa")
    b.add_argument("--out", required=True, help="output directory")
    b.add_argument("--overwrite", action="store_true", help="replace existing files")
    b.add_argument("--force", action="store_true",
                   help="run a plan over the limit (2e8 samples on the fine grid, 1000 "
                        "recordings); without it such a plan is refused, saying its size")
    b.add_argument("-q", "--quiet", action="store_true")

    s = sub.add_parser(
        "simulate", help="simulate a model card on a recording's inputs",
        description="Run MODEL.json on the recording's command, position and supply from "
                    "its first measured pressure; write time_s,pressure_Pa.")
    s.add_argument("recording", help="recording .csv/.json path or stem")
    s.add_argument("--model", required=True, help="model card (pneubayes-model/1 JSON)")
    s.add_argument("--out", required=True, help="output CSV (time_s,pressure_Pa)")
    s.add_argument("--rtol", type=POSITIVE, default=3e-5, help="relative tolerance (3e-5, as "
                   "SolverConfig.standard)")
    s.add_argument("--atol", type=POSITIVE, default=10.0, help="absolute tolerance, Pa (10)")
    s.add_argument("--max-step", type=POSITIVE, default=0.02, help="largest step, s (0.02)")
    s.add_argument("--overwrite", action="store_true")
    _add_accept(s)

    f = sub.add_parser(
        "fit", help="identify a model: paper least squares, refinement, emcee posterior",
        description="Fit the thin-port model (and effects) to recordings: the paper's "
                    "eq.-10 least squares on fixed-volume recordings, multiple shooting on "
                    "prediction windows (--horizon, 2 s by default), then an emcee "
                    "posterior. Writes RUNDIR/model.json (posterior median), posterior.nc, "
                    "summary.json, chain.h5 (a killed run resumes), run.json, figures/.")
    f.add_argument("recordings", nargs="+", help="recording .csv/.json paths or stems")
    f.add_argument("--out", required=True, help="run folder")
    f.add_argument("--model", help="model card whose effects (and options) to fit")
    f.add_argument("--effects", default=None,
                   help="effects of the fitted model when no --model (default: the paper's "
                        "cylinder_leak; '' for the plain thin-port model)")
    f.add_argument("--leak-form", default=None, choices=("orifice", "laminar"),
                   help="law of the fitted cylinder_leak (default orifice, the paper's); "
                        "only with cylinder_leak among --effects")
    f.add_argument("--known-from", default=None, metavar="RUN|MODEL.json",
                   help="a fit of the same rig card (its run folder or model.json): the "
                        "card's fitted quantities are known at that fit's values, except "
                        "those named by --refit (a valve identified once; a lung "
                        "recalibrated per recording)")
    f.add_argument("--refit", type=parameter_names, default=(), metavar="NAME[,NAME]",
                   help="with --known-from: the card quantities (parameter names) fitted "
                        "again")
    f.add_argument("--method", default="mcmc", choices=("lsq", "refine", "mcmc", "laplace"),
                   help="lsq: the paper's eq.-10 least squares only; refine: then multiple "
                        "shooting on the windows; mcmc (default): then the emcee posterior; "
                        "laplace: then a Gaussian at the posterior's mode (minutes where "
                        "emcee takes hours; no skew, one mode)")
    _add_fit_settings(f)
    _add_run_options(f)

    r = sub.add_parser(
        "predict", help="posterior-predictive pressure bands (--horizon windows) for a recording",
        description="Rolling windows from the measured pressure with the posterior "
                    "predictive mean and 5/50/95 % bands; PRED.metrics.json holds RMSE, "
                    "band coverage and the noise floor.")
    r.add_argument("run", help="run folder written by 'pneubayes fit'")
    r.add_argument("recording", help="recording .csv/.json path or stem")
    r.add_argument("--horizon", type=POSITIVE, default=None,
                   help="window length, s (default: the run's, 2 s for older runs)")
    r.add_argument("--stride", type=POSITIVE, default=None, help="window spacing (= horizon)")
    r.add_argument("--draws", type=POSITIVE_INT, default=200,
                   help="posterior draws (200; at least 20 for the 5-95 %% bands)")
    r.add_argument("--seed", type=NON_NEGATIVE_INT, default=0)
    r.add_argument("--out", required=True, help="output CSV")
    r.add_argument("--no-figure", action="store_true")
    r.add_argument("--overwrite", action="store_true")
    r.add_argument("--force", action="store_true",
                   help="predict over 20,000 windows or 2e7 simulated samples (window samples x "
                        "draws; refused without it, saying the cost)")
    _add_accept(r)

    d = sub.add_parser(
        "discover", help="find which physical effect the model misses, add it, verify",
        description="Start from the plain thin-port model; fit; map where predictions and "
                    "measurements disagree; run grouped SINDy on the dp/dt residual with "
                    "physically named candidate terms; add the best-supported effect, "
                    "refit, and keep it only if held-out predictions improve; repeat. "
                    "Writes RUNDIR/discovery.json, model.json, disagreement.json, "
                    "report.md and figures/.")
    d.add_argument("recordings", nargs="+", help="recording .csv/.json paths or stems")
    d.add_argument("--out", required=True, help="run folder (an interrupted run resumes)")
    d.add_argument("--held-out", nargs="+", default=[], metavar="REC",
                   help="recordings held out whole to verify (triggered trials, whose ends "
                        "hold no valve event); else the end of every recording is "
                        "(data.holdout_fraction, 1/3)")
    _add_settings_file(d, "DiscoverySettings: [data], [search], [verify], [rounds], "
                          "[forms], [stages], [fit], [posterior], seed; docs/discovery.md")
    d.add_argument("--set", action="append", type=assignment, default=[],
                   metavar="KEY=VALUE",
                   help="one setting of the tree by its dotted name, applied last; "
                        "repeatable; e.g. rounds.max_effects=2, stages.pair_members=0, "
                        "fit.sampler.n_walkers=64, data.bounds.dead_volume_m3=[1e-5,5e-3], "
                        "search.grid.strengths.sensor_calibration=[2000,5000,10000] (the "
                        "only way to search for sensor_calibration, whose terms are off by "
                        "default)")
    d.add_argument("--max-effects", action=_Retired,
                   replacement="is now --set rounds.max_effects=N")
    d.add_argument("--posterior", choices=["emcee", "laplace", "none"], default=None,
                   help="posterior.method: the final model's posterior: emcee (default), "
                        "laplace (a Gaussian at the posterior's mode from a few hundred "
                        "evaluations: minutes where emcee on a model with a tube takes "
                        "hours; no skew, one mode) or none (refined point estimates)")
    d.add_argument("--seed", type=NON_NEGATIVE_INT, default=None,
                   help="seed and fit.sampler.seed: the search's bags and the sampler (0; "
                        "recorded)")
    _add_horizon(d)
    _add_pressure_filter(d)
    _add_run_options(d)

    im = sub.add_parser(
        "import", help="convert third-party recordings to the recording format plus a rig "
                       "card (the inputs are never modified)")
    im.add_argument("source", choices=["gtdynamics", "respiraworks"],
                    help="gtdynamics: trial folders of the GTDynamics jumping robot; "
                         "respiraworks: the ventilator's AIR/ and OXY/ covent_pc_N.dat runs")
    im.add_argument("inputs", nargs="+", help="the data set's trial folders or files")
    im.add_argument("--out", required=True, help="folder for the recordings and rig card")
    im.add_argument("--end", type=POSITIVE, default=None, metavar="S",
                    help="keep samples up to this time, s (gtdynamics: 0.33, before the "
                         "muscles are vented by something not in the command)")
    im.add_argument("--overwrite", action="store_true",
                    help="write into a non-empty --out folder")
    _add_limits(im)

    a = sub.add_parser(
        "ablate", help="run a declarative ablation study (a grid of fits) with caching",
        description="Run every cell of STUDY.toml (rigs x data effects x data forms x "
                    "model effects x command ranges x protocols x seeds): bench data, fit, "
                    "held-out 2-s prediction RMSE. Each cell is cached in "
                    "RUNDIR/cells/ID.json as it finishes, so an interrupted study resumes; "
                    "a failed cell records its error and traceback, the study goes on, "
                    "and running again retries it. Writes RUNDIR/results.json and "
                    "results.csv. Exit 1 if any cell failed.")
    a.add_argument("study", help="study TOML file (see experiments/studies/smoke.toml)")
    a.add_argument("--out", required=True, help="run folder (an interrupted run resumes)")
    a.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask distributed cluster at this scheduler address "
                        "(needs pip install 'pneubayes[dask]')")
    a.add_argument("--workers", type=POSITIVE_INT, default=None,
                   help="local worker processes (default 1: in this process)")
    a.add_argument("--smoke", action="store_true",
                   help="one cell (the first value of every axis) with short recordings")
    _add_run_folder(a)
    a.add_argument("--dry-run", action="store_true",
                   help="validate the study and list its cells; run and write nothing")
    a.add_argument("--keep-work", action="store_true",
                   help="keep each cell's bench recordings and fit folder in RUNDIR/work")
    a.add_argument("-q", "--quiet", action="store_true", help="no progress output")

    _add_resume(sub)
    _add_track(sub)
    _add_compile(sub)
    return p


def _add_resume(sub) -> None:
    """The ``resume`` subcommand's parser."""
    r = sub.add_parser(
        "resume", help="continue a stopped fit, discover or ablate run (an error if its "
                       "folder holds none)",
        description="Run again the command that started RUN (the command line recorded in "
                    "RUN/run.json), insisting on a resume: an error when RUN holds no run, "
                    "or when that command's inputs or settings no longer match the run's "
                    "(a recording changed, say), instead of starting anew. Run it from the "
                    "folder the command was started in if its paths were relative. The "
                    "same command run again resumes as well; this one never starts over.")
    r.add_argument("run", help="the run folder (the --out of fit, discover or ablate)")


def _add_track(sub) -> None:
    """The ``track`` subcommand's parser."""
    t = sub.add_parser(
        "track", help="replay a recording as a stream: the varying quantities' posterior "
                      "tick by tick and its predictions",
        description="A particle filter (pneubayes.inference.online; --method particles) "
                    "or a refit of the run so far anchored at the run's values "
                    "(pneubayes.inference.online_refit; --method refit) over the "
                    "quantities --vary names, the model's others at the run's values, "
                    "takes the recording one --tick at a time; per tick OUT.json records their "
                    "5/50/95 % quantiles and the error of the --horizon prediction from "
                    "the measured pressure (online and the frozen fit's) with the 90 % "
                    "band's coverage. Nothing is written over an input.")
    t.add_argument("run", help="run folder with a model.json ('pneubayes fit' or 'discover')")
    t.add_argument("recording", help="recording .csv/.json path or stem")
    t.add_argument("--vary", type=parameter_names, required=True, metavar="NAME[,NAME]",
                   help="the quantities tracked (model parameter names, e.g. "
                        "lung_compliance_m3_per_Pa,resistance_Pa_s_per_m3; particles: with "
                        "a lower bound > 0; refit: 'all' for every parameter)")
    t.add_argument("--method", choices=("particles", "refit"), default="particles",
                   help="particles (default): a particle filter over --vary; refit: "
                        "--vary refitted on the run so far every --refit-every seconds, "
                        "anchored at the run's values (a Gaussian prior of SD "
                        "--relative-sd of each quantity's scale), its posterior Laplace")
    t.add_argument("--relative-sd", type=POSITIVE, default=0.3,
                   help="refit: the anchor's SD as a fraction of each quantity's scale (0.3)")
    t.add_argument("--refit-every", type=POSITIVE, default=None, metavar="S",
                   help="refit: seconds of new samples between refits (default: --horizon)")
    t.add_argument("--out", required=True, help="output JSON")
    t.add_argument("--tick", type=POSITIVE, default=0.1,
                   help="seconds of samples per update (0.1)")
    t.add_argument("--horizon", type=POSITIVE, default=None,
                   help="prediction length, s (default: the run's, 2 s for older runs)")
    t.add_argument("--particles", type=POSITIVE_INT, default=64, help="particles (64)")
    t.add_argument("--draws", type=POSITIVE_INT, default=64,
                   help="resampled particles per prediction (64)")
    t.add_argument("--predict-every", type=POSITIVE_INT, default=1, metavar="TICKS",
                   help="predict every this many ticks (1)")
    t.add_argument("--noise-std", type=POSITIVE, default=None, metavar="PA",
                   help="the model's prediction error, Pa, the likelihood's Gaussian scale "
                        "(default: the run's refined RMSE)")
    t.add_argument("--prior", choices=("fit", "bounds"), default="fit",
                   help="fit (default): log-normal at the run's values, spread "
                        "--prior-log-sd; bounds: log-uniform over the model's bounds")
    t.add_argument("--prior-log-sd", type=POSITIVE, default=0.5,
                   help="the fit prior's standard deviation of the log (0.5)")
    t.add_argument("--lookback", type=POSITIVE, default=1.0,
                   help="each tick's predictions start this many seconds back (1.0)")
    t.add_argument("--temper", type=share, default=0.1,
                   help="the likelihood's power in (0, 1] (0.1: correlated model errors)")
    t.add_argument("--update-mode", choices=("lookback", "carried"), default="lookback",
                   help="lookback (default): every tick re-simulates --lookback seconds; "
                        "carried: each particle carries its model state and a tick "
                        "simulates only its new samples (a cost that does not grow with "
                        "--lookback, which then sets the moves' memory)")
    t.add_argument("--pressure-gain", type=share, default=1.0,
                   help="carried mode: the share of a particle's error by which its "
                        "pressure moves to the measured one at each tick (1: the measured; "
                        "0: its own, open loop)")
    t.add_argument("--seed", type=NON_NEGATIVE_INT, default=0)
    t.add_argument("--overwrite", action="store_true")
    _add_accept(t)


def _add_compile(sub) -> None:
    """The ``compile`` subcommand's parser."""
    k = sub.add_parser(
        "compile", help="compile the simulator's kernels now, so the first fit does not "
                        "wait for the compiler",
        description="Compile every variant of the simulation kernel, and the virtual "
                    "test bench's plant, into numba's cache beside the package (once per "
                    "install or upgrade; about two minutes on one core), the variants in "
                    "parallel processes. Later processes load the cache instead of "
                    "compiling.")
    k.add_argument("--jobs", type=POSITIVE_INT, default=2,
                   help="processes compiling at once (default 2)")


def check_single_values(parser, args) -> None:
    """argparse lets ``--opt=--`` through as an empty list, unconverted: refuse any
    single-valued option whose value is a list, as a usage error naming it."""
    subparsers = next(a for a in parser._actions
                      if isinstance(a, argparse._SubParsersAction))
    sub = subparsers.choices[args.command]
    for action in sub._actions:
        value = getattr(args, action.dest, None)
        if (type(action) is argparse._StoreAction and action.nargs is None
                and action.option_strings and isinstance(value, list)):
            sub.error(f"argument {'/'.join(action.option_strings)}: expected one value")
