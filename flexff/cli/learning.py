"""`flexff train`, `export` and `identify`: a model trained on a dataset, exported to ONNX,
and the dataset's physics prior identified (learning/)."""

from __future__ import annotations

import argparse
import json

from flexff.cli.shared import MODELS, PRESETS, Commands, device_option, output_file


def _train(args: argparse.Namespace) -> int:
    """One run into OUTPUT, or with several --seed or a --scheduler one run per seed into
    OUTPUT/seedN, side by side (learning.workers); prints the metrics as JSON."""
    from flexff.learning.workflow import train_model

    metrics = train_model(args.model, args.data, args.output, args.preset, args.seed or [0],
                          args.epochs, args.labels, args.force_input, args.resume, args.force,
                          args.checkpoint_every, args.scheduler, args.device, args.cuda_graphs)
    print(json.dumps(metrics, indent=2, default=str))
    return 0


def _export(args: argparse.Namespace) -> int:
    from flexff.learning.export import export

    output_file(args.output)
    print(f"wrote {export(args.run, args.output, inputs=args.inputs)}")
    return 0


def _identify(args: argparse.Namespace) -> int:
    from flexff.learning.identify import Identification, relative_gains
    from flexff.learning.workflow import identify_prior

    identified = identify_prior(args.data, args.output, args.env)
    identification, path = identified.model, identified.path
    if not isinstance(identification, Identification):  # a machine's linear model
        print(identification.summary())
        print(f"wrote {path}")
        return 0
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
