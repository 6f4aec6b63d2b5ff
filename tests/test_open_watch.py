"""The kernel's open watch sees every file a process opens, whatever opens it (Python, a native reader, another thread,
a program it runs, a process it starts), with the access asked; the calls that would open past it fail; a process
started by a watched one sees its own opens and not its parent's."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.apps.navigation import open_watch

SERVER = r"""
import ctypes, errno, json, os, subprocess, sys, threading
import cv2, numpy as np
from st_sim.apps.navigation import open_watch

libc = ctypes.CDLL(None, use_errno=True)
libc.fopen.restype = ctypes.c_void_p

def native(path):
    handle = libc.fopen(os.fsencode(path), b"rb")
    assert handle, path
    libc.fclose(ctypes.c_void_p(handle))

def relative(path):
    folder = os.open(os.path.dirname(path), os.O_RDONLY | os.O_DIRECTORY)
    os.close(os.open(os.path.basename(path), os.O_RDONLY, dir_fd=folder))
    os.close(folder)

def in_thread(path):
    thread = threading.Thread(target=lambda: open(path, "rb").close())
    thread.start()
    thread.join()

READERS = {
    "python": lambda path: open(path, "rb").close(),
    "numpy": lambda path: np.fromfile(path, np.uint8),
    "imread": lambda path: cv2.imread(path, cv2.IMREAD_UNCHANGED),
    "fopen": native,
    "dir_fd": relative,
    "thread": in_thread,
    "program": lambda path: subprocess.run(["cat", path], stdout=subprocess.DEVNULL, check=True),
    "write": lambda path: open(path, "ab").close(),
    "read and write": lambda path: open(path, "r+b").close(),
}

def raw(name):
    number = open_watch.SYSCALLS[os.uname().machine][1][name]
    libc.syscall.restype = ctypes.c_long
    result = libc.syscall(ctypes.c_long(number), ctypes.c_long(-100), b"/etc/hostname", None, ctypes.c_long(0))
    return -1 if result >= 0 else ctypes.get_errno()

print(json.dumps({"started": open_watch.start(), "why": open_watch.unavailable()}), flush=True)
for line in sys.stdin:
    ask = json.loads(line)
    if ask["do"] == "refused":
        print(json.dumps({name: raw(name) for name in ("openat2", "io_uring_setup")}), flush=True)
        continue
    if ask["do"] == "child":  # a process it starts, which joins the watch and reports its own opens
        child = subprocess.Popen([sys.executable, "-c", CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 text=True)
        assert child.stdout.readline().strip() == "marked"
        open(ask["parent_reads"], "rb").close()  # the parent's open, after the child's mark
        out, _ = child.communicate(ask["child_reads"] + "\n")
        print(out.strip(), flush=True)
        continue
    mark = open_watch.mark()
    READERS[ask["do"]](ask["path"])
    print(json.dumps(open_watch.opened_since(mark)), flush=True)
"""

CHILD = """
import json, sys
from st_sim.apps.navigation import open_watch
started = open_watch.start()
mark = open_watch.mark()
print("marked", flush=True)
path = sys.stdin.readline().strip()
open(path, "rb").close()
print(json.dumps({"started": started, "why": open_watch.unavailable(), "opened": open_watch.opened_since(mark)}))
"""


class Watched:
    """A process that starts the watch and reads files as it is told, answering with what the watch saw."""

    def __init__(self):
        code = SERVER.replace("CHILD", repr(CHILD))
        self.process = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        text=True, cwd=Path(__file__).parents[1])
        self.started = json.loads(self.process.stdout.readline())

    def ask(self, **request: str) -> object:
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        return json.loads(self.process.stdout.readline())


@pytest.fixture(scope="module")
def watched() -> Iterator[Watched]:
    process = Watched()
    assert process.started == {"started": True, "why": None}, "Linux here: the watch must run"
    yield process
    process.process.stdin.close()
    process.process.wait(timeout=30)


def png(path: Path) -> Path:
    import cv2
    import numpy as np

    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path.with_suffix(".png")), np.full((2, 3), 7, np.uint8))
    path.with_suffix(".png").rename(path)  # the name as drawn, whatever its suffix
    return path


NAMES = st.text(st.characters(blacklist_categories=("Cs", "Cc"), blacklist_characters="/\\"), min_size=1,
                max_size=24).filter(lambda name: name not in (".", "..") and len(name.encode()) < 200)


@settings(max_examples=40, deadline=None)
@given(name=NAMES, folder=st.sampled_from(["", "sub dir", "a/b/c", "dés"]),
       reader=st.sampled_from(["python", "numpy", "imread", "fopen", "dir_fd", "thread", "program",
                               "read and write"]))
def test_every_reader_is_seen_reading_any_file(watched: Watched, tmp_path_factory: pytest.TempPathFactory,
                                                name: str, folder: str, reader: str) -> None:
    path = png(tmp_path_factory.mktemp("files") / folder / name).resolve()
    seen = watched.ask(do=reader, path=str(path))
    assert [str(path), "r"] in seen, (reader, seen)


def test_a_file_opened_to_write_is_seen_as_written(watched: Watched, tmp_path: Path) -> None:
    seen = watched.ask(do="write", path=str(tmp_path / "out.bin"))
    assert [str(tmp_path / "out.bin"), "w"] in seen and [str(tmp_path / "out.bin"), "r"] not in seen


def test_the_calls_that_would_open_past_the_watch_fail_as_unsupported(watched: Watched) -> None:
    assert watched.ask(do="refused") == {"openat2": 38, "io_uring_setup": 38}  # ENOSYS


def test_a_process_started_by_a_watched_one_joins_the_watch_and_sees_its_own_opens_only(
        watched: Watched, tmp_path: Path) -> None:
    parent_reads, child_reads = png(tmp_path / "parent.bin"), png(tmp_path / "child.bin")
    report = watched.ask(do="child", parent_reads=str(parent_reads), child_reads=str(child_reads))
    assert report["started"] and report["why"] is None, report
    assert [str(child_reads), "r"] in report["opened"], report
    assert [str(parent_reads), "r"] not in report["opened"], "the parent's open is not the child's"


def filtered_here() -> bool:
    """Whether this process runs under a seccomp filter (a watch started by an earlier test of this worker)."""
    return any(line.split() == ["Seccomp:", "2"] for line in Path("/proc/self/status").read_text().splitlines())


@pytest.mark.parametrize("address", [None, "1:stcrowd-open-watch-gone", "not an address"])
def test_a_process_watches_unless_a_filter_it_cannot_join_is_in_place(address: str | None) -> None:
    """The property every other test of the identity leans on: a fresh process starts the watch, also when it
    inherited a watcher's address but not its filter (the variable copied by hand). A process under a watch it cannot
    join (this worker's filter, inherited, without its address) is not watched and says why."""
    env = {key: value for key, value in os.environ.items() if key != open_watch.ADDRESS_VARIABLE}
    env |= {} if address is None else {open_watch.ADDRESS_VARIABLE: address}
    code = "from st_sim.apps.navigation import open_watch; print(open_watch.start(), open_watch.unavailable())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    if filtered_here():
        assert out.startswith("False ") and "another supervisor watches this process" in out, out
    else:
        assert out.split() == ["True", "None"], out


def test_a_forked_child_asks_on_its_own_socket_and_sees_its_own_opens(tmp_path: Path) -> None:
    """A child made by fork (no exec) inherits its parent's socket to the watcher: it joins anew, and each sees its
    own opens only."""
    code = f"""
import json, multiprocessing
from st_sim.apps.navigation import open_watch
def child(queue):
    mark = open_watch.mark()
    open({str(tmp_path / "child.bin")!r}, "wb").close()
    queue.put(open_watch.opened_since(mark))
assert open_watch.start()
mark = open_watch.mark()
context = multiprocessing.get_context("fork")
queue = context.Queue()
process = context.Process(target=child, args=(queue,))
process.start()
seen = queue.get()
process.join()
open({str(tmp_path / "parent.bin")!r}, "wb").close()
print(json.dumps({{"child": seen, "parent": open_watch.opened_since(mark)}}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).parents[1]).stdout
    report = json.loads(out)
    assert [str(tmp_path / "child.bin"), "w"] in report["child"]
    assert [str(tmp_path / "parent.bin"), "w"] not in report["child"]
    assert [str(tmp_path / "parent.bin"), "w"] in report["parent"]
    assert [str(tmp_path / "child.bin"), "w"] in report["parent"], "a child's opens are its parent's too"


@settings(max_examples=100, deadline=None)
@given(parents=st.dictionaries(st.integers(2, 40), st.integers(0, 40), max_size=30),
       opens=st.lists(st.tuples(NAMES, st.sampled_from("rw"), st.integers(2, 40)), max_size=30),
       asker=st.integers(2, 40), since=st.integers(0, 35))
def test_the_watcher_answers_each_process_with_its_own_and_its_descendants_opens(
        parents: dict[int, int], opens: list[tuple[str, str, int]], asker: int, since: int) -> None:
    """Whatever the process tree (loops included: a reused pid), a process's answer holds exactly the opens after
    its mark whose process descends from it, in order, every path and access as recorded."""
    log = open_watch.OpenLog()
    log.parent_of, log.opened = dict(parents), [("/" + name, access, owner) for name, access, owner in opens]

    def descends(owner: int) -> bool:
        seen = set()
        while owner not in seen:
            if owner == asker:
                return True
            seen.add(owner)
            owner = parents.get(owner, 0)
        return False

    expected = [(path, access) for path, access, owner in log.opened[since:] if descends(owner)]
    assert open_watch._entries(log.reply(since, asker)) == expected
    count, _ = open_watch._REQUEST.unpack(log.reply(-1, asker))
    assert count == len(opens)
