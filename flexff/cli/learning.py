"""`flexff train`, `export` and `identify`: a model trained on a dataset, exported to ONNX,
and the dataset's physics prior identified (learning/)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from flexff.cli.shared import MODELS, PRESETS, Commands, device_option, epochs, output_file
from flexff.fmu.errors import InputError


def _train(args: argparse.Namespace) -> int:
    """One run into OUTPUT, or with several --seed or a --scheduler one run per seed into
    OUTPUT/seedN, side by side (learning.workers); prints the metrics as JSON."""
    from flexff.learning.machine_dataset import is_machine_dataset

    if is_machine_dataset(args.data):
        return _train_machine(args)
    overrides = {"labels": args.labels, **epochs(args),
                 **({"force_input": True} if args.force_input else {}),
                 **({"cuda_graphs": True} if args.cuda_graphs else {})}
    seeds = args.seed or [0]
    if len(seeds) == 1 and args.scheduler is None:
        from flexff.learning.train import train

        metrics = train(args.model, args.preset, args.data, args.output, resume=args.resume,
                        force=args.force, checkpoint_every=args.checkpoint_every,
                        **overrides, seed=seeds[0], device=args.device)
        print(json.dumps(metrics, indent=2, default=str))
        return 0
    from flexff.learning.workers import TrainJob, train_parallel

    if args.resume or args.force or args.checkpoint_every is not None:
        raise InputError("--resume, --force and --checkpoint-every go with one seed trained "
                         "here; several seeds resume what their folders hold")
    if len(set(seeds)) != len(seeds):
        raise InputError(f"--seed: each seed once, got {seeds}")
    jobs = [TrainJob(args.model, args.preset, Path(args.data), Path(args.output) / f"seed{s}",
                     {**overrides, "seed": s}, label=f"seed{s}") for s in seeds]
    results = train_parallel(jobs, scheduler=args.scheduler, device=args.device)
    print(json.dumps(results, indent=2, default=str))
    return 0


def _train_machine(args: argparse.Namespace) -> int:
    """train on a machine's dataset: one seed, on features with the friction widths of its
    prior identified on it (the prior itself for pgnn)."""
    from flexff.learning.machine_dataset import load_machine_dataset
    from flexff.learning.machine_evaluate import learned_features
    from flexff.learning.machine_identify import identify_dataset
    from flexff.learning.machine_train import fit_machine
    from flexff.learning.presets import make_config

    if len(args.seed or [0]) > 1 or args.scheduler is not None or args.labels != "forces" \
            or args.force_input:
        raise InputError("a machine's dataset trains one seed here, on its efforts, without "
                         "--force-input (its physics is the pgnn's prior)")
    data = load_machine_dataset(args.data)
    config = make_config(args.model, args.preset, seed=(args.seed or [0])[0],
                         device=args.device, **epochs(args))
    identified = identify_dataset(data)
    metrics = fit_machine(config, data.description, data.sample_rate_hz, data.trajectories,
                          data.digest, Path(args.output), learned_features(identified),
                          resume=args.resume, force=args.force,
                          checkpoint_every=args.checkpoint_every,
                          prior=identified if args.model == "pgnn" else None)
    print(json.dumps(metrics, indent=2, default=str))
    return 0


def _export(args: argparse.Namespace) -> int:
    from flexff.learning.export import export

    output_file(args.output)
    print(f"wrote {export(args.run, args.output, inputs=args.inputs)}")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from flexff.cosim.run import output_folder
    from flexff.learning.evaluate import preprocessing
    from flexff.learning.identify import REPORT, identify, relative_gains, write_identification
    from flexff.learning.machine_dataset import is_machine_dataset

    output_folder(args.output)  # a folder, as for every command: made, or refused, first
    if is_machine_dataset(args.data):
        from flexff.learning.linear_model import write_linear_model
        from flexff.learning.machine_dataset import load_machine_dataset
        from flexff.learning.machine_identify import dataset_features, identify_dataset

        data = load_machine_dataset(args.data)
        features, settings = dataset_features(data)
        print(settings)
        model = identify_dataset(data, features)
        print(model.summary())
        print(f"wrote {write_linear_model(model, Path(args.output) / REPORT)}")
        return 0

    identification = identify(args.data, preprocessing(args.env))
    path = write_identification(identification, args.output)
    rows = identification.rows()
    width = max(len(row["base"]) for row in rows)
    print(f"{'base parameter':<{width}} {'value':>12} {'std':>10}  unit")
    for row in rows:
        std = f"{row['std']:10.3g}" if row["estimated"] else f"{'(nominal)':>10}"
        print(f"{row['base']:<{width}} {row['value']:12.5g} {std}  {row['unit']}")
    print(f"motor friction tanh width w_stribeck: {identification.w_stribeck:g} rad/s; "
          f"{identification.samples} samples")
    relative = " / ".join(f"{k:.4f}" for k in relative_gains(identification.gains))
    print(f"torque constants relative to one another (motors 1 / 2 / 3): {relative}")
    for label, (x, y) in (("residual", identification.residual_rms),
                          ("nominal model's error", identification.nominal_rms),
                          ("forces", identification.label_rms)):
        print(f"{label}: {x:.3g} / {y:.3g} N rms (x / y)")
    print(f"wrote {path} (use it with [feedforward] kind = \"rigid-body\", identified = "
          f"\"{path}\")")
    return 0


def add_commands(commands: Commands) -> None:
    """Add `train`, `export` and `identify`."""
    train = commands.add_parser("train", help="train a feedforward model on a dataset folder")
    train.add_argument("--model", required=True, choices=MODELS, help="the network")
    train.add_argument("--preset", default="fast", choices=PRESETS,
                       help="fast: minutes on a laptop CPU; "
                            "thesis: the thesis's network sizes (GPU)")
    train.add_argument("--data", required=True,
                       help="a dataset folder (flexff data collect or data import)")
    train.add_argument("-o", "--output", required=True, help="the run folder to write")
    train.add_argument("--epochs", type=int, help="override the preset's number of epochs")
    train.add_argument("--labels", default="forces", choices=("forces", "currents"),
                       help="what the model learns and feeds forward: the efforts the loop "
                            "commands (default; a machine's axes' efforts, the manipulator's "
                            "wrist force Fx, Fy), or, on the manipulator, the motor currents "
                            "i1..i3, added after the control allocation")
    train.add_argument("--force-input", action="store_true",
                       help="give a black-box network the force of the rigid-body model "
                            "identified on the training split as two more inputs")
    existing = train.add_mutually_exclusive_group()
    existing.add_argument("--resume", action="store_true",
                          help="continue the unfinished run in the run folder from its last "
                               "checkpoint (same settings and data)")
    existing.add_argument("--force", action="store_true",
                          help="train into a run folder that is not empty, starting afresh "
                               "(a finished run's files stay until the new ones are complete)")
    train.add_argument("--checkpoint-every", type=int, metavar="N",
                       help="epochs between checkpoints (default: the preset's)")
    train.add_argument("--seed", type=int, action="append", metavar="S",
                       help="the training seed (default 0); repeated, one run per seed into "
                            "OUTPUT/seedS, side by side (flexff export takes them as an "
                            "ensemble)")
    train.add_argument("--scheduler", help="address of a Dask scheduler to train on (its "
                                           "workers see this file system)")
    device_option(train, "train on")
    train.add_argument("--cuda-graphs", action="store_true",
                       help="on CUDA, replay each training step from a CUDA graph (2.8 to 6 "
                            "times faster an epoch on an H200; off by default, see the GPU "
                            "how-to)")
    train.set_defaults(handler=_train)

    export = commands.add_parser("export", help="export a training run (or an ensemble of "
                                                "runs) to ONNX")
    export.add_argument("run", nargs="+", help="the run folder (flexff train); several runs "
                                               "of one model kind give one graph of their mean")
    export.add_argument("-o", "--output", required=True, help="the .onnx file to write")
    export.add_argument("--inputs", default="features", choices=("features", "reference"),
                        help="graph inputs: the SI features, or the reference signals "
                             "(x_ref .. ay_ref) with the features computed in the graph")
    export.set_defaults(handler=_export)

    identification = commands.add_parser(
        "identify", help="identify a dataset's physics prior by least squares (a machine's "
                         "terms, or the manipulator's rigid-body model)")
    identification.add_argument("data", help="a dataset folder (its training split is used)")
    identification.add_argument("-o", "--output", required=True,
                                help="the folder to write identified.json into (made if "
                                     "missing; an existing folder is written into)")
    identification.add_argument("--env", default="hardware", choices=("sim", "hardware"),
                                help="a manipulator dataset: preprocess as flexff evaluate's "
                                     "environment does: hardware (the thesis's: encoders "
                                     "counted, 1.8 Hz; for measured or noisy encoders) or sim "
                                     "(ideal encoders); a machine's dataset derives its own")
    identification.set_defaults(handler=_identify)
