"""`flexff evaluate`, `predict`, `tune` and `ilc`: the feedforward's tracking against PID
alone, a model's predictions on logs, a loop's PID tuning and iterative learning control."""

from __future__ import annotations

import argparse

from flexff.cli.shared import (
    MODELS,
    PRESETS,
    Commands,
    device_option,
    ilc_options,
    machine_options,
    output_file,
)

FILES = {  # what `flexff evaluate` says it wrote, by what it evaluated (learning.workflow)
    "machine": "results in {out}/ (summary.json, table.md, errors.png, identified.json, data/, "
               "runs/, models/, fmus/, ilc/ for the limit)",
    "logs": "relative 2-norm of the effort error on the test logs; results in {out}/ "
            "(summary.json, table.md, identified.json, runs/, models/)",
    "manipulator": "results in {out}/ (summary.json, table.md, paths.png, errors.png, "
                   "forces.png, the .onnx models, ilc/ for the limit, held-out/ for the test "
                   "split's references)",
}


def _evaluate(args: argparse.Namespace) -> int:
    from flexff.cosim.run import load_run_config
    from flexff.learning.workflow import evaluate_any

    train, test = args.trajectories
    evaluation = evaluate_any(
        args.output, args.env, None if args.config is None else load_run_config(args.config),
        args.data, args.models, args.preset, args.epochs, args.device, args.scheduler,
        args.currents, None if args.ilc_labels is None else
        [kind for kind in args.ilc_labels if kind != "none"], args.force_input, train, test,
        args.duration, args.classes, args.ilc_iterations, args.ilc_cutoff, args.ilc_gain)
    print((evaluation.out / "table.md").read_text())
    print(FILES[evaluation.kind].format(out=args.output))
    return 0


def _predict(args: argparse.Namespace) -> int:
    """predict RUN --data LOGS -o FILE.csv: each model's efforts per sample of the logs."""
    from flexff.learning.machine_features import preprocessing_text
    from flexff.learning.predict import predict_logs, write_predictions

    output_file(args.output)
    predictions = predict_logs(args.run, args.data, args.split)
    print(preprocessing_text(predictions.preprocessing))
    written = write_predictions(predictions, args.output,
                                {"run": str(args.run), "data": str(args.data),
                                 "split": args.split})
    for name, errors in predictions.relative_error.items():
        print(f"{name}: " + ", ".join(f"{axis} {100 * e:.2f} %" for axis, e in errors.items()))
    print(f"relative 2-norm of the filtered effort error; wrote {', '.join(map(str, written))}")
    return 0


def _tune(args: argparse.Namespace) -> int:
    """tune LOOP: each axis's plant measured in the loop, the PID block's loop shape proposed."""
    from flexff.cosim.run import load_run_config
    from flexff.learning.pid_tune import tune_loop, tuning_table, write_tuning

    output_file(args.output)
    tuning = tune_loop(load_run_config(args.config), args.phase_margin, args.seconds,
                       args.high_hz)
    print(tuning_table(tuning))
    print(f"wrote {write_tuning(tuning, args.output, args.config)} (the PID block's mass, "
          f"damping and crossover_hz per axis; margins around the identified model)")
    return 0


def _ilc(args: argparse.Namespace) -> int:
    from flexff.cosim.metrics import metrics_axes
    from flexff.cosim.run import load_run_config
    from flexff.learning.ilc import NOISE_FLOOR, RESULT, ilc

    state = ilc(load_run_config(args.config), args.output, args.iterations, args.cutoff,
                gain=args.gain)
    for trial in state["trials"]:
        axes = metrics_axes(trial)
        e2 = ", ".join(f"{trial[a]['e2']:.4g}" for a in axes)
        ratio = ", ".join(f"{trial[a]['e2_ratio']:.4g}" for a in axes)
        unit = " m/sqrt(s)" if axes == ["x", "y"] else f" ({', '.join(axes)})"
        print(f"trial {trial['trial']}: e2 = ({e2}){unit}, PID alone / trial = ({ratio})")
    print(f"best: trial {state['best']}; its feedforward force -> {args.output}/{RESULT} "
          f"(ilc.json, e2.png beside it)")
    if floor := state[NOISE_FLOOR]:
        print(f"noise floor: e2 = ({', '.join(f'{v:.4g}' for v in floor.values())}) "
              f"({', '.join(floor)}), what the measurement's noise and quantization add; no "
              f"feedforward goes below it")
    return 0


def add_commands(commands: Commands) -> None:
    """Add `evaluate`, `predict`, `tune` and `ilc`."""
    evaluation = commands.add_parser(
        "evaluate", help="collect, train, export, co-simulate the loop with each feedforward "
                         "and report its tracking against PID alone (on the manipulator, the "
                         "thesis's Table 5.2 or 6.2); with --data of imported logs, each "
                         "model's effort prediction")
    evaluation.add_argument("--env", default="sim", choices=("sim", "hardware"),
                            help="the manipulator's environment, without --config or --data: "
                                 "sim (Table 5.2) or hardware (Table 6.2)")
    evaluation.add_argument("--config", metavar="CONFIG.toml|SYSTEM.ssp",
                            help="collect and evaluate on this loop (flexff's controller and "
                                 "any plant) instead of the environment's plant")
    evaluation.add_argument("-o", "--output", required=True, help="the output folder")
    evaluation.add_argument("--preset", default="fast", choices=PRESETS)
    evaluation.add_argument("--models", nargs="+", default=list(MODELS), choices=MODELS)
    evaluation.add_argument("--currents", nargs="+", default=[], metavar="KIND",
                            choices=MODELS,
                            help="the manipulator: also the current-level model of these kinds: "
                                 "labels i1..i3, fed forward after the control allocation")
    evaluation.add_argument("--ilc-labels", nargs="+", metavar="KIND",
                            choices=(*MODELS, "none"),
                            help="also these kinds trained on the force iterative learning "
                                 "control learns on each training reference (2 trials each); "
                                 "default: pgnn on --env hardware, where --models has it; "
                                 "none: no ILC labels"),
    evaluation.add_argument("--force-input", nargs="+", default=[], metavar="KIND",
                            choices=[m for m in MODELS if m != "pgnn"],
                            help="also these black-box kinds with the identified rigid-body "
                                 "force as two more inputs (on the ILC labels too where "
                                 "--ilc-labels names the kind)")
    evaluation.add_argument("--data", help="a collected dataset folder to use; a machine's "
                                           "imported logs alone: each model's force "
                                           "prediction on the test logs")
    evaluation.add_argument("--epochs", type=int, help="override the preset's number of epochs")
    evaluation.add_argument("--scheduler", help="address of a Dask scheduler to collect and "
                                                "train on (its workers see this file system)")
    device_option(evaluation, "train the networks on")
    machine_options(evaluation)
    ilc_options(evaluation, "--ilc-")
    evaluation.set_defaults(handler=_evaluate)

    prediction = commands.add_parser(
        "predict", help="each trained model's predicted effort per sample of a machine's logs "
                        "beside the measured one (raw and filtered), as CSV, JSON and PNG")
    prediction.add_argument("run", help="flexff evaluate's output folder (identified.json, "
                                        "runs/) or one training run folder")
    prediction.add_argument("--data", required=True,
                            help="a machine dataset folder (flexff data import --machine)")
    prediction.add_argument("-o", "--output", required=True,
                            help="the CSV file to write (its .json and .png beside it)")
    prediction.add_argument("--split", default="all", choices=("all", "train", "test"),
                            help="the dataset's trajectories to predict (default all)")
    prediction.set_defaults(handler=_predict)

    tune = commands.add_parser(
        "tune", help="measure each axis's plant in a loop (a chirp) and propose its PID "
                     "block's mass, damping and crossover_hz for a phase margin, as TOML")
    tune.add_argument("config", metavar="CONFIG.toml|SYSTEM.ssp",
                      help="the loop with a [machine] (its PID closed while measuring)")
    tune.add_argument("-o", "--output", required=True, help="the TOML file to write")
    tune.add_argument("--phase-margin", type=float, default=40.0, metavar="DEG",
                      help="the phase margin to keep (default 40)")
    tune.add_argument("--seconds", type=float, default=8.0, metavar="S",
                      help="the chirp's length per axis (default 8)")
    tune.add_argument("--high-hz", type=float, metavar="HZ",
                      help="the chirp's highest frequency, the highest crossover proposed "
                           "(default 5 %% of the loop's rate)")
    tune.set_defaults(handler=_tune)

    learning = commands.add_parser(
        "ilc", help="iterative learning control on a run's one reference: the best feedforward "
                    "force for it, as a CSV table a run can use (resumes an interrupted one)")
    learning.add_argument("config", metavar="CONFIG.toml|SYSTEM.ssp",
                          help="the loop and its reference (flexff's controller, any plant; "
                               "its own feedforward is replaced)")
    learning.add_argument("-o", "--output", required=True, help="the output folder")
    ilc_options(learning, "--")
    learning.set_defaults(handler=_ilc)
