"""A config's table kept in the cache (issue 36: ``gainsched paper`` without a checkout):
built on first use with the bytes ``gainsched build`` writes, found again after, rebuilt
when damaged, one file per config; the checkout's own table comes first when it is the
config's. tests/sim/test_closed_loop.py flies ``gainsched paper`` from the cache."""

from __future__ import annotations

import shutil

from gainsched.config import load_config
from gainsched.model.reduced import Model
from gainsched.schedule.cached import cached_table, cached_table_path
from gainsched.schedule.grid import build_grid
from gainsched.schedule.tables import table_bytes

from support import PAPER_H5, small_config


def test_built_once_with_the_bytes_of_a_build(tmp_path, monkeypatch):
    monkeypatch.setenv("GAINSCHED_CACHE", str(tmp_path / "cache"))
    cfg = small_config()
    path = cached_table_path(cfg)
    assert path.parent == tmp_path / "cache" / "tables" and not path.exists()
    calls = []
    table, built = cached_table(cfg, progress=calls.append)
    assert built and path.is_file() and calls == [1, 1]  # one call per speed
    assert table.config_sha256 == cfg.sha256
    # what `gainsched build` writes as small.h5 (firmware.outputs.output_set)
    assert path.read_bytes() == table_bytes(cfg, build_grid(cfg), Model(cfg))
    again, built = cached_table(cfg)
    assert not built and again.config_sha256 == cfg.sha256
    other = small_config(**{"vehicle.mass": 0.55})
    assert cached_table_path(other) != path and cached_table_path(other).name.startswith("small-")


def test_a_damaged_cached_table_is_built_again(tmp_path, monkeypatch):
    monkeypatch.setenv("GAINSCHED_CACHE", str(tmp_path))
    cfg = small_config()
    cached_table(cfg)
    path = cached_table_path(cfg)
    good = path.read_bytes()
    path.write_bytes(good[: len(good) // 2])
    _, built = cached_table(cfg)
    assert built and path.read_bytes() == good


def test_paper_command_prefers_the_working_folders_table_then_the_cache(tmp_path,
                                                                       monkeypatch):
    """``gainsched paper`` without --tables (:func:`gainsched.studies.table_for`):
    tables/paper.h5 of the working folder (the checkout's, here) when it was built from
    the config; elsewhere (an installed package), the cache's."""
    from gainsched.studies import table_for

    monkeypatch.setenv("GAINSCHED_CACHE", str(tmp_path / "cache"))
    paper = load_config("paper")
    monkeypatch.chdir(PAPER_H5.parents[1])
    table, path = table_for(paper)
    assert path.resolve() == PAPER_H5 and table.config_sha256 == paper.sha256
    monkeypatch.chdir(tmp_path)
    seeded = cached_table_path(paper)
    seeded.parent.mkdir(parents=True)
    shutil.copyfile(PAPER_H5, seeded)  # as a first use would have left it
    table, path = table_for(paper)
    assert path == seeded and table.config_sha256 == paper.sha256
