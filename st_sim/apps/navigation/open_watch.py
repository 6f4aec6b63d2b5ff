"""Every file a process opens, as the kernel sees it: Python's ``open``, a native reader (OpenCV's ``imread``, a C
library's ``fopen``), a program it runs, in any thread or child process.

    if open_watch.start():                      # once per process: from here on, every open is seen
        mark = open_watch.mark()
        cv2.imread("weights.png")
        open_watch.opened_since(mark)           # [("/abs/weights.png", "r"), ...]

How: the process sets a seccomp filter (Linux's system-call filter; unprivileged once ``no_new_privs`` is set) that
hands every ``open``, ``openat``, ``execve`` and ``execveat`` to a watcher: a small Python process started before the
filter, which reads the path from the caller's memory, resolves it against the caller's working folder or folder
descriptor, records it with the access asked (``"w"`` to write only, create or truncate, else ``"r"``) and lets the
call go on (``SECCOMP_USER_NOTIF_FLAG_CONTINUE``). Calls that would open a file past the watcher (``openat2``,
``io_uring``, ``open_by_handle_at``, another ABI's system calls) fail with ``ENOSYS``, which their callers treat as
"not supported" and fall back from. A call whose path the watcher cannot read (where Yama lets a process read the
memory of its descendants only: a child that has not joined the watch yet, a program it runs) goes on and is
recorded as ``UNREAD``: seen, not identified (a benchmark chunk then refuses its episodes).

The filter stays for the life of the process and of the processes it starts: ``fingerprint.ReadAudit`` starts it,
so a process that audits a benchmark run (the ``benchmark`` or ``verify`` command, a grid worker) is watched until it
ends. What it sees is what the code asks the kernel for: code
in the process that rewrites a path while the kernel reads it, or that rewrites this module's records, deceives it,
as it could deceive any record kept in its own process. Linux on x86-64 or AArch64, kernel 5.7 or later; elsewhere
``start`` returns False and says why (``unavailable``).

This module imports only the standard library: the watcher runs it as a script.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import os
import platform
import select
import socket
import struct
import subprocess
import sys
import threading

SYSCALLS = {  # machine -> (audit arch, {name: number}), from the kernel's unistd tables
    "x86_64": (0xC000003E, {"open": 2, "openat": 257, "execve": 59, "execveat": 322, "openat2": 437,
                            "io_uring_setup": 425, "open_by_handle_at": 304, "seccomp": 317}),
    "aarch64": (0xC00000B7, {"openat": 56, "execve": 221, "execveat": 281, "openat2": 437,
                             "io_uring_setup": 425, "open_by_handle_at": 265, "seccomp": 277}),
}
WATCHED = ("open", "openat", "execve", "execveat")
"""system calls handed to the watcher"""
REFUSED = ("openat2", "io_uring_setup", "open_by_handle_at")
"""system calls that would open files unseen: they fail with ENOSYS"""
UNREAD = "?"
"""the path recorded for an open whose path the watcher could not read"""
X32_BIT = 0x40000000  # x86-64's x32 ABI marks its system call numbers with this bit

_RET_ALLOW, _RET_USER_NOTIF, _RET_ERRNO = 0x7FFF0000, 0x7FC00000, 0x00050000
_FLAG_TSYNC, _FLAG_NEW_LISTENER, _FLAG_TSYNC_ESRCH = 1, 8, 16
_PR_SET_NO_NEW_PRIVS, _PR_SET_PTRACER = 38, 0x59616D61
_NOTIF_RECV, _NOTIF_SEND, _NOTIF_ID_VALID = 0xC0502100, 0xC0182101, 0x40082102
_NOTIF = struct.Struct("=QIIiIQ6Q")  # id, pid, flags, then seccomp_data: nr, arch, instruction pointer, args
_RESPONSE = struct.Struct("=QqiI")  # id, val, error, flags
_CONTINUE = 1
_REQUEST = struct.Struct("=qq")  # a question to the watcher: since which mark (-1: the mark now), for which process
_LENGTH = struct.Struct("=I")  # an answer's length, before it
_ENTRY = struct.Struct("=cI")  # one open in an answer: its access, its path's length (the path follows)
READY = b"ready"
PATH_MAX = 4096

ADDRESS_VARIABLE = "STCROWD_OPEN_WATCH"
"""the environment variable through which a watched process's children find its watcher (an abstract socket)"""

_state: dict[str, object] = {}  # "pid" it belongs to, "lock"; "socket" to the watcher, or "error" where start failed


def start() -> bool:
    """Watch every open of this process and its children from now on (once per process; later calls return at
    once). A process started by a watched one is watched already (the filter is inherited): it joins its ancestor's
    watcher and sees its own opens and its children's. True if the watch runs, False if this system cannot
    (``unavailable`` says why)."""
    if _state.get("pid") != os.getpid():  # a forked child: the socket it inherited is its parent's
        _state.clear()
        _state.update(pid=os.getpid(), lock=threading.Lock())
    if "socket" in _state or "error" in _state:
        return "socket" in _state
    for connect in ((_join, _install) if os.environ.get(ADDRESS_VARIABLE) else (_install,)):
        try:  # a process that inherited the address but not the filter (the variable copied by hand) installs its own
            _state["socket"] = connect()
            _probe()
            _state.pop("error", None)
            return True
        except OSError as err:
            if "socket" in _state:
                _state.pop("socket").close()  # type: ignore[attr-defined]
            _state["error"] = str(err)
    return False


def unavailable() -> str | None:
    """Why ``start`` could not watch this process; None if it watches, or has not been tried."""
    return _state.get("error") if _state.get("pid") == os.getpid() else None  # type: ignore[return-value]


def mark() -> int:
    """A mark of the opens recorded so far (0 where there is no watch)."""
    return _REQUEST.unpack(_ask(-1))[0] if _watching() else 0


def opened_since(mark_: int) -> list[tuple[str, str]]:
    """The opens of this process and its children recorded after ``mark_`` (``mark``), in order, as (absolute path,
    "r" or "w"); a path the watcher could not read is ``UNREAD``. Empty where there is no watch."""
    if not _watching():
        return []
    return _entries(_ask(mark_))


def _watching() -> bool:
    """Whether this process is watched; a forked child of a watched process joins the watch here."""
    if "socket" in _state and _state.get("pid") != os.getpid():
        start()
    return "socket" in _state


def _probe() -> None:
    """OSError unless the watcher records an open of this process (a stale address would name another's)."""
    before = mark()
    os.close(os.open(os.devnull, os.O_RDONLY))
    if (os.devnull, "r") not in opened_since(before):
        raise OSError("the open watcher this process reached does not see its opens")


def _ask(since: int) -> bytes:
    """The watcher's answer about this process's opens after mark ``since`` (-1: the mark now)."""
    sock: socket.socket = _state["socket"]  # type: ignore[assignment]
    with _state["lock"]:  # type: ignore[attr-defined]
        sock.sendall(_REQUEST.pack(since, os.getpid()))
        reply = _receive(sock)
    if reply is None:
        raise RuntimeError("the open watcher of this process is gone")
    return reply


def _join() -> socket.socket:
    """The socket to the watcher that an ancestor started (``ADDRESS_VARIABLE``: its pid and address): this process
    inherited its filter, and lets the watcher read its memory where Yama would not."""
    pid, _, address = os.environ[ADDRESS_VARIABLE].partition(":")
    if pid.isdigit():
        ctypes.CDLL(None).prctl(_PR_SET_PTRACER, int(pid), 0, 0, 0)  # without Yama: fails harmless
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.connect("\0" + address)
    except OSError as err:
        sock.close()
        raise OSError(f"the open watcher of the process that started this one is gone ({err})") from None
    return sock


def _install() -> socket.socket:
    """Start the watcher, set the filter, hand the watcher its listener; the socket to ask the watcher on."""
    machine = platform.machine()
    if sys.platform != "linux" or machine not in SYSCALLS:
        raise OSError(f"the open watch needs Linux on {' or '.join(SYSCALLS)} (this is {sys.platform} {machine})")
    arch, numbers = SYSCALLS[machine]
    address = f"stcrowd-open-watch-{os.getpid()}-{os.urandom(8).hex()}"
    ours, theirs = socket.socketpair()
    watcher = subprocess.Popen([sys.executable, "-I", "-S", __file__, str(theirs.fileno()), address],
                               pass_fds=[theirs.fileno()], stdin=subprocess.DEVNULL, close_fds=True)
    theirs.close()
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PTRACER, watcher.pid, 0, 0, 0)  # where Yama limits reading memory to ancestors: fails harmless
    if libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0:
        raise _os_error(ctypes.get_errno(), "prctl(PR_SET_NO_NEW_PRIVS)")
    code = _filter(arch, numbers, x32=machine == "x86_64")
    program = ctypes.create_string_buffer(code)
    fprog = ctypes.create_string_buffer(struct.pack("=HxxxxxxQ", len(code) // 8, ctypes.addressof(program)))
    libc.syscall.restype = ctypes.c_long
    listener = libc.syscall(ctypes.c_long(numbers["seccomp"]), ctypes.c_long(1),  # SECCOMP_SET_MODE_FILTER
                            ctypes.c_long(_FLAG_TSYNC | _FLAG_NEW_LISTENER | _FLAG_TSYNC_ESRCH), fprog)
    if listener < 0:
        err = ctypes.get_errno()
        watcher.kill()
        raise _os_error(err, "seccomp(SET_MODE_FILTER, NEW_LISTENER)" + (
            " (another supervisor watches this process's system calls)" if err == errno.EBUSY else ""))
    socket.send_fds(ours, [b"L"], [listener])
    os.close(listener)
    if _receive(ours) != READY:
        raise OSError("the open watcher did not start")
    os.environ[ADDRESS_VARIABLE] = f"{watcher.pid}:{address}"  # for the processes it starts: watched by its watcher
    return ours


def _os_error(number: int, call: str) -> OSError:
    return OSError(number, f"{call} failed: {os.strerror(number)}")


def _filter(arch: int, numbers: dict[str, int], x32: bool) -> bytes:
    """The classic BPF program: another ABI, or x32, fails with ENOSYS; WATCHED go to the watcher; REFUSED fail
    with ENOSYS; the rest is allowed."""
    def op(code: int, jt: int, jf: int, k: int) -> bytes:
        return struct.pack("=HBBI", code, jt, jf, k)

    load, jeq, jge, ret = 0x20, 0x15, 0x35, 0x06  # BPF_LD|W|ABS, BPF_JMP|JEQ|K, BPF_JMP|JGE|K, BPF_RET|K
    watched = [numbers[name] for name in WATCHED if name in numbers]
    refused = [numbers[name] for name in REFUSED if name in numbers]
    checks = [*watched, *refused]
    body = [op(load, 0, 0, 0)]  # the system call's number
    if x32:
        body.append(op(jge, len(checks) + 2, 0, X32_BIT))  # -> ENOSYS
    for i, number in enumerate(checks):
        left = len(checks) - i - 1  # checks after this one
        to_notify, to_refuse = left + 1, left + 2
        body.append(op(jeq, to_notify if i < len(watched) else to_refuse, 0, number))
    body += [op(ret, 0, 0, _RET_ALLOW), op(ret, 0, 0, _RET_USER_NOTIF), op(ret, 0, 0, _RET_ERRNO | errno.ENOSYS)]
    head = [op(load, 0, 0, 4), op(jeq, 1, 0, arch), op(ret, 0, 0, _RET_ERRNO | errno.ENOSYS)]  # the ABI
    return b"".join(head + body)


def _send(sock: socket.socket, body: bytes) -> None:
    sock.sendall(_LENGTH.pack(len(body)) + body)


def _receive(sock: socket.socket) -> bytes | None:
    """One message (its length, then its bytes); None once the other end has closed."""
    head = _read_exactly(sock, _LENGTH.size)
    return None if head is None else _read_exactly(sock, _LENGTH.unpack(head)[0])


def _entries(body: bytes) -> list[tuple[str, str]]:
    """The (path, access) pairs of a reply: each an access byte, the path's length and its bytes."""
    entries, at = [], 0
    while at < len(body):
        access, size = _ENTRY.unpack_from(body, at)
        at += _ENTRY.size
        entries.append((os.fsdecode(body[at:at + size]), access.decode()))
        at += size
    return entries


def _read_exactly(sock: socket.socket, size: int) -> bytes | None:
    data = bytearray()
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        if not chunk:
            return None
        data += chunk
    return bytes(data)


# --- the watcher: a process of its own, never filtered ---------------------------------------------------------


def watch(fd: int, address: str) -> None:
    """The watcher's loop: take the listener from the socket ``fd``, answer every notification, and the questions
    of the watched process (on ``fd``) and of its children (on the abstract socket ``address``); end when the
    process that started it has closed ``fd``."""
    starter = socket.socket(fileno=fd)
    _, fds, _, _ = socket.recv_fds(starter, 1, 1)
    listener = fds[0]
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind("\0" + address)
    server.listen()
    log = OpenLog()
    _send(starter, READY)
    clients = {starter.fileno(): starter}
    poll = select.poll()
    for ready in (listener, server.fileno(), starter.fileno()):
        poll.register(ready, select.POLLIN)
    while True:
        for ready, _ in poll.poll():
            if ready == listener:
                log.answer(listener)
            elif ready == server.fileno():
                client, _ = server.accept()
                clients[client.fileno()] = client
                poll.register(client.fileno(), select.POLLIN)
            else:
                client = clients[ready]
                request = _read_exactly(client, _REQUEST.size)
                if request is None:
                    if client is starter:
                        return
                    poll.unregister(ready)
                    client.close()
                    del clients[ready]
                    continue
                _send(client, log.reply(*_REQUEST.unpack(request)))


class OpenLog:
    """The watcher's record: every open, in order, with the process (thread group) that asked for it, and each
    process's parent as first seen (so a process's children's opens are its own too, even once orphaned)."""

    def __init__(self):
        self.opened: list[tuple[str, str, int]] = []  # (path, access, process id)
        self.process_of: dict[int, int] = {}  # thread id -> process id
        self.parent_of: dict[int, int] = {}  # process id -> parent process id

    def reply(self, since: int, pid: int) -> bytes:
        """The mark now for ``since`` -1, else the opens of ``pid`` and its descendants after mark ``since``."""
        if since < 0:
            return _REQUEST.pack(len(self.opened), pid)
        return b"".join(_ENTRY.pack(access.encode(), len(name)) + name for path, access, owner in self.opened[since:]
                        if self._within(owner, pid) for name in (os.fsencode(path),))

    def _within(self, owner: int, pid: int) -> bool:
        seen = set()
        while owner not in seen and owner > 1:
            if owner == pid:
                return True
            seen.add(owner)
            owner = self.parent_of.get(owner, 0)
        return owner == pid

    def answer(self, listener: int) -> None:
        """Receive one notification, record its path (``UNREAD`` where it cannot be read), let the call go on."""
        buffer = bytearray(_NOTIF.size)
        try:
            fcntl.ioctl(listener, _NOTIF_RECV, buffer, True)
        except OSError:  # the caller died meanwhile
            return
        notif_id, tid, _, number, _, _, *args = _NOTIF.unpack(buffer)
        name = _NAMES.get(number, "")
        at = name in ("openat", "execveat")
        dirfd = ctypes.c_int(args[0]).value if at else -100  # AT_FDCWD
        path = _read_path(tid, args[1] if at else args[0])
        access = "r" if name.startswith("exec") else _access(args[2] if at else args[1])
        resolved = None if path is None else _resolve(tid, dirfd, path)
        owner = self._owner(tid)
        try:
            fcntl.ioctl(listener, _NOTIF_ID_VALID, struct.pack("=Q", notif_id))
        except OSError:  # the caller died, its id may be another's now: nothing read is trusted
            return
        self.opened.append((resolved if resolved is not None else UNREAD, access, owner))
        with contextlib.suppress(OSError):  # the caller died meanwhile
            fcntl.ioctl(listener, _NOTIF_SEND, bytearray(_RESPONSE.pack(notif_id, 0, 0, _CONTINUE)))

    def _owner(self, tid: int) -> int:
        """The process of thread ``tid``, its parent noted the first time it is seen."""
        if tid not in self.process_of:
            fields = {}
            try:
                with open(f"/proc/{tid}/status") as status:
                    for line in status:
                        key, _, value = line.partition(":")
                        if key in ("Tgid", "PPid"):
                            fields[key] = int(value)
            except (OSError, ValueError):
                return tid
            self.process_of[tid] = fields.get("Tgid", tid)
            self.parent_of.setdefault(self.process_of[tid], fields.get("PPid", 0))
        return self.process_of[tid]


def _access(flags: int) -> str:
    """"w" for flags that write only, create or truncate (O_WRONLY, O_CREAT, O_TRUNC), else "r": a file opened to read
    and write (O_RDWR) without them is read, and its contents are what it held."""
    return "w" if flags & 0o1 or flags & (0o100 | 0o1000) else "r"


def _read_path(pid: int, address: int) -> str | None:
    """The NUL-terminated path at ``address`` in ``pid``'s memory, page by page; None where it cannot be read."""
    try:
        memory = os.open(f"/proc/{pid}/mem", os.O_RDONLY)
    except OSError:
        return None
    try:
        data = b""
        while len(data) < PATH_MAX:
            page_left = 4096 - (address + len(data)) % 4096
            block = os.pread(memory, page_left, address + len(data))
            if not block:
                return None
            end = block.find(b"\0")
            if end >= 0:
                return os.fsdecode(data + block[:end])
            data += block
        return None
    except OSError:
        return None
    finally:
        os.close(memory)


def _resolve(pid: int, dirfd: int, path: str) -> str | None:
    """``path`` made absolute against ``pid``'s working folder (``dirfd`` AT_FDCWD) or the folder ``dirfd`` holds;
    the caller's own ``/proc/self`` named by its pid; None where the base cannot be read."""
    if not path.startswith("/"):
        try:
            base = os.readlink(f"/proc/{pid}/cwd" if dirfd == -100 else f"/proc/{pid}/fd/{dirfd}")
        except OSError:
            return None
        path = os.path.join(base, path) if path else base
    for alias in ("/proc/self/", "/proc/thread-self/"):
        if path.startswith(alias):
            path = f"/proc/{pid}/" + path.removeprefix(alias)
    return os.path.normpath(path)


_NAMES = {number: name for name, number in SYSCALLS.get(platform.machine(), (0, {}))[1].items()}

if __name__ == "__main__":
    watch(int(sys.argv[1]), sys.argv[2])
