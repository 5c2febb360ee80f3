"""A disk that fills up while a figure or a dataset's splits are written.

The writer fails with ``OSError(ENOSPC)`` after part of the file is out (faked: the real write
runs, then the file is cut in half and the error raised). The command then ends with one
``scpformer: error:`` line naming the file, the file that was there before is unchanged, and
no temporary file is left beside it.
"""

from __future__ import annotations

import errno
import pathlib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from scpformer.cli.main import main

OLD = b"an earlier figure"


def no_space(path: object) -> OSError:
    return OSError(errno.ENOSPC, "No space left on device", str(path))


@pytest.fixture
def savefig_fills_the_disk(monkeypatch):
    """``Figure.savefig`` writes half its file, then fails as a full disk does."""
    real = Figure.savefig

    def half_then_full(self, fname, *args, **kwargs):
        real(self, fname, *args, **kwargs)
        data = Path(fname).read_bytes()
        Path(fname).write_bytes(data[: len(data) // 2])
        raise no_space(fname)

    monkeypatch.setattr(Figure, "savefig", half_then_full)


def one_line_error(capsys, argv: list[str], status: int, *texts: str) -> str:
    """Run ``scpformer argv``: ``status`` and one stderr line naming each of ``texts``."""
    assert main(argv) == status
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("scpformer: error: "), err
    assert all(text in lines[0] for text in texts), lines[0]
    assert "Traceback" not in out + err
    return lines[0]


def names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*"))


# -- figures --------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "rendezvous", "--problem", "tpbvp"],
        ["solve", "pdg6dof"],
    ],
    ids=["rendezvous", "pdg6dof"],
)
@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_a_full_disk_while_plotting_keeps_the_earlier_figure(
    tmp_path, capsys, savefig_fills_the_disk, argv, suffix
):
    figure = tmp_path / f"fig{suffix}"
    figure.write_bytes(OLD)
    one_line_error(capsys, [*argv, "--plot", str(figure)], 1, "No space left on device",
                   str(figure))  # fmt: skip
    assert figure.read_bytes() == OLD
    assert names(tmp_path) == [figure.name]  # no temporary file, no history figure


def test_a_full_disk_while_plotting_the_robust_rendezvous_keeps_the_earlier_figure(
    tmp_path, savefig_fills_the_disk
):
    from scpformer.plotting.robust_rendezvous import plot_solution
    from scpformer.problems.robust_rendezvous.instance import RobustInstance

    instance = RobustInstance()
    x = np.linspace(instance.x0_rtn, instance.xf_rtn, instance.n_nodes + 1)
    u = np.zeros((instance.n_nodes, 3))
    figure = tmp_path / "robust.png"
    figure.write_bytes(OLD)
    with pytest.raises(OSError, match="No space left on device") as err:
        plot_solution(instance, x, u, figure)
    assert err.value.filename == str(figure)  # the figure, not the temporary name
    assert figure.read_bytes() == OLD and names(tmp_path) == [figure.name]


def small_figure() -> Figure:
    from scpformer.experiments.report import new_figure

    figure, axes = new_figure(ncols=1, width=2.0, height=2.0)
    axes.plot([0, 1], [1, 0])
    return figure


def test_a_full_disk_while_saving_a_report_figure_keeps_the_earlier_one(
    tmp_path, savefig_fills_the_disk
):
    from scpformer.experiments.report import save_figure

    figure = tmp_path / "fig4_cost.png"
    figure.write_bytes(OLD)
    with pytest.raises(OSError, match="No space left on device") as err:
        save_figure(small_figure(), figure)
    assert err.value.filename == str(figure)
    assert figure.read_bytes() == OLD and names(tmp_path) == [figure.name]


def test_a_full_disk_while_plotting_training_losses_keeps_the_earlier_plot(
    tmp_path, savefig_fills_the_disk
):
    from scpformer.train.metrics import LOSS_PLOT_NAME, EpochRecord, plot_losses

    plot = tmp_path / LOSS_PLOT_NAME
    plot.write_bytes(OLD)
    history = [EpochRecord(epoch=1, train_loss=1.0, val_loss=2.0, lr=1e-3, seconds=1.0,
                           samples_per_s=10.0, loading_share=0.1)]  # fmt: skip
    with pytest.raises(OSError, match="No space left on device"):
        plot_losses(tmp_path, history, title="art")
    assert plot.read_bytes() == OLD and names(tmp_path) == [plot.name]


@pytest.mark.parametrize("suffix", [".png", ".pdf", ".svg"])
def test_figures_written_through_a_temporary_name_keep_their_format(tmp_path, suffix):
    """The temporary name ends in the figure's suffix: matplotlib picks the format by it."""
    from scpformer.experiments.report import save_figure

    path = tmp_path / f"figure{suffix}"
    save_figure(small_figure(), path)
    magic = {".png": b"\x89PNG", ".pdf": b"%PDF", ".svg": b"<?xml"}[suffix]
    assert path.read_bytes().startswith(magic) and names(tmp_path) == [path.name]


# -- dataset splits -------------------------------------------------------------------------
@pytest.fixture
def toy_dataset(tmp_path, monkeypatch):
    """6 instances of the data tests' toy family (it solves in microseconds), split."""
    import importlib

    from scpformer.data.generate import GenerateConfig, generate

    monkeypatch.syspath_prepend(str(Path(__file__).parent / "data"))  # workers import it too
    family = importlib.import_module("toy_families").ToyFamily()
    folder = tmp_path / "ds"
    generate(family, GenerateConfig(n=6, out=folder, shard_size=3, workers=1, seed=2))
    return folder


def test_a_full_disk_while_splitting_keeps_the_earlier_splits(toy_dataset, capsys, monkeypatch):
    assert main(["dataset", "split", str(toy_dataset)]) == 0
    capsys.readouterr()
    splits = toy_dataset / "splits.h5"
    before = {p.name: p.read_bytes() for p in toy_dataset.iterdir() if p.is_file()}
    real = pathlib.Path.write_bytes

    def half_then_full(self, data):
        if "splits.h5" not in self.name:
            return real(self, data)
        real(self, data[: len(data) // 2])
        raise no_space(self)

    monkeypatch.setattr(pathlib.Path, "write_bytes", half_then_full)
    argv = ["dataset", "split", str(toy_dataset), "--seed", "5", "--force"]
    one_line_error(capsys, argv, 1, "disk full", str(splits), "nothing was changed")
    assert {p.name: p.read_bytes() for p in toy_dataset.iterdir() if p.is_file()} == before
    assert not [name for name in names(toy_dataset) if "tmp" in name]
    monkeypatch.undo()
    assert main(argv) == 0  # with space again, the new splits replace the old
    assert splits.read_bytes() != before["splits.h5"]
