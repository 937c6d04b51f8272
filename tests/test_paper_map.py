"""Fetching the paper's map: downloaded from a local HTTP server that serves ../shared/maps,
checked against the pinned checksums, pooled to the 5 m grid, cached, and fetched again when a
cached file is corrupted. No test reaches outside the machine."""

from __future__ import annotations

import functools
import hashlib
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from marl_cover import paper_map
from marl_cover.paper_map import (
    PAPER_MAP_SHA256,
    SOURCE_SHA256,
    PaperMapUnavailable,
    fetch_paper_map,
    npy_bytes,
    pool_occupancy,
)

SHARED_MAPS = Path(__file__).resolve().parents[2] / "shared" / "maps"


class _Server:
    """A local HTTP server on 127.0.0.1 serving one folder; counts the files it served."""

    def __init__(self, folder: Path) -> None:
        requests: list[str] = []

        class Handler(SimpleHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                requests.append(self.path)
                super().do_GET()

            def log_message(self, *args: object) -> None:
                pass

        handler = functools.partial(Handler, directory=str(folder))
        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.requests = requests
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)
        self.thread.start()

    def url(self, name: str) -> str:
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/{name}"

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture
def server() -> Iterator[_Server]:
    if not (SHARED_MAPS / "grid_slice2.npy").is_file():
        pytest.skip(f"no {SHARED_MAPS / 'grid_slice2.npy'} to serve")
    served = _Server(SHARED_MAPS)
    yield served
    served.close()


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_pooling_and_the_published_layout_give_the_published_file() -> None:
    fine = np.zeros((11, 12), dtype=bool)
    fine[0, 0] = fine[9, 9] = fine[10, 11] = True  # the last row and columns are dropped
    assert pool_occupancy(fine).tolist() == [[True, False], [False, True]]
    if not (SHARED_MAPS / "grid_slice2.npy").is_file():
        pytest.skip("no shared maps")
    derived = npy_bytes(pool_occupancy(np.load(SHARED_MAPS / "grid_slice2.npy")))
    assert derived == (SHARED_MAPS / "grid_slice10.npy").read_bytes()


def test_fetch_downloads_once_checks_and_caches(server: _Server, tmp_path: Path) -> None:
    url = server.url("grid_slice2.npy")
    path = fetch_paper_map(tmp_path, url=url)
    assert path == tmp_path / "grid_slice10.npy"
    assert _sha(path) == PAPER_MAP_SHA256
    assert _sha(tmp_path / "grid_slice2.npy") == SOURCE_SHA256
    assert path.read_bytes() == (SHARED_MAPS / "grid_slice10.npy").read_bytes()
    assert server.requests == ["/grid_slice2.npy"]
    assert fetch_paper_map(tmp_path, url=url) == path
    assert len(server.requests) == 1  # the cache answered
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid_slice10.npy", "grid_slice2.npy"]


def test_a_corrupted_cache_is_named_and_fetched_again(
    server: _Server, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    url = server.url("grid_slice2.npy")
    path = fetch_paper_map(tmp_path, url=url)
    source = tmp_path / "grid_slice2.npy"
    data = bytearray(source.read_bytes())
    data[-1] ^= 1
    source.write_bytes(bytes(data))
    path.write_bytes(path.read_bytes()[:-1] + b"\x01")
    with caplog.at_level(logging.WARNING, logger="marl_cover.paper_map"):
        assert fetch_paper_map(tmp_path, url=url) == path
    warned = " ".join(r.getMessage() for r in caplog.records)
    assert f"{path}: SHA-256" in warned and f"{source}: SHA-256" in warned
    assert f"expected {PAPER_MAP_SHA256}" in warned
    assert len(server.requests) == 2  # the bad source was downloaded again
    assert _sha(path) == PAPER_MAP_SHA256 and _sha(source) == SOURCE_SHA256


def test_a_download_of_another_file_is_refused(server: _Server, tmp_path: Path) -> None:
    with pytest.raises(PaperMapUnavailable, match="SHA256 hash of downloaded file"):
        fetch_paper_map(tmp_path, url=server.url("grid_slice10.npy"))
    assert not (tmp_path / "grid_slice10.npy").exists()


def test_offline_the_error_names_the_command_the_url_and_the_variable(tmp_path: Path) -> None:
    closed = _Server(tmp_path)  # a port that was just freed: nothing listens there
    url = closed.url("grid_slice2.npy")
    closed.close()
    with pytest.raises(PaperMapUnavailable) as error:
        fetch_paper_map(tmp_path / "cache", url=url)
    message = str(error.value)
    assert url in message
    assert "marl-cover fetch-map" in message
    assert "$MARL_COVER_PAPER_MAP" in message


def test_paper_map_path_uses_the_cache_and_fetches_on_first_use(
    server: _Server, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("MARL_COVER_PAPER_MAP", raising=False)
    monkeypatch.setenv("MARL_COVER_CACHE", str(tmp_path))
    monkeypatch.setattr(paper_map, "_checkout_copies", lambda: [])
    with pytest.raises(PaperMapUnavailable, match="MARL_COVER_OFFLINE forbids downloading"):
        paper_map.paper_map_path()
    monkeypatch.delenv("MARL_COVER_OFFLINE")
    monkeypatch.setattr(paper_map, "SOURCE_URL", server.url("grid_slice2.npy"))
    assert paper_map.paper_map_path() == tmp_path / "grid_slice10.npy"
    monkeypatch.setenv("MARL_COVER_OFFLINE", "1")  # now the cache answers, offline too
    assert paper_map.paper_map_path() == tmp_path / "grid_slice10.npy"
    assert len(server.requests) == 1


def test_the_fetch_command_prints_the_cached_path(server: _Server, tmp_path: Path) -> None:
    command = [
        "-m",
        "marl_cover.agents.cli.main",
        "fetch-map",
        f"url={server.url('grid_slice2.npy')}",
    ]
    env = {**os.environ, "MARL_COVER_CACHE": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, *command],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=True,
    )
    assert done.stdout.strip() == str(tmp_path / "grid_slice10.npy")
    assert _sha(tmp_path / "grid_slice10.npy") == PAPER_MAP_SHA256
