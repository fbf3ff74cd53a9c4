"""Identification for any machine (`flexff identify --data DIR` on a machine dataset): the
linear model of the description's prior (learning.linear_model) fitted on a dataset's training
trajectories, their motion and efforts filtered as the networks' labels are. It needs no
PyTorch.
"""

from __future__ import annotations

from flexff.learning.linear_model import identify_linear, parallel_filter
from flexff.learning.linear_prior import LinearModel
from flexff.learning.machine_dataset import MachineDataset
from flexff.learning.machine_features import (
    MachineFeatures,
    motion,
    named_motion,
    preprocessing,
    preprocessing_text,
)


def dataset_features(data: MachineDataset) -> tuple[MachineFeatures, str]:
    """The description's feature settings (`[machine.learning]`) resolved on the dataset's
    training trajectories, and a line saying what they are, each derived one marked."""
    given = MachineFeatures.of(data.description)
    resolved = given.resolved(data.sample_rate_hz, [t.signals for t in data.split("train")],
                              data.description)
    return resolved, preprocessing_text(preprocessing(given, resolved, data.sample_rate_hz))


def identify_dataset(data: MachineDataset, features: MachineFeatures | None = None
                     ) -> LinearModel:
    """The prior's linear model identified on the training trajectories: the regressor of
    their measured motion and their efforts through the labels' low-pass alike, decimated to
    two samples a corner period (learning.linear_model.parallel_filter: its standard
    deviations then hold), the filter's ends left out."""
    machine = data.description
    rate_hz = data.sample_rate_hz
    train = [t for t in data.trajectories if t.split == "train"]
    resolved = (features or MachineFeatures.of(machine)).resolved(
        rate_hz, [t.signals for t in train], machine)
    motions, efforts = [], []
    for trajectory in train:
        moved, effort = motion(trajectory.signals, rate_hz, machine, resolved)
        motions.append(named_motion(moved, machine))
        efforts.append({a.name: effort[:, k] for k, a in enumerate(machine.axes)})
    assert resolved.cutoff_hz is not None and resolved.lead_s is not None
    return identify_linear(machine, motions, efforts,
                           parallel_filter(rate_hz, resolved.cutoff_hz, resolved.filter_order),
                           resolved.lead_s)
