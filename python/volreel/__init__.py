"""volreel: time-varying volumes encoded for random access, from Python.

    import volreel
    c = volreel.open("turbulence.vreel")      # a folder, or an http(s):// URL of one
    c.dims, c.frames, c.times, c.levels, c.value_range, c.bps
    a = c.frame(3)                             # numpy float32 [z, y, x], the finest level
    coarse = c.frame(3, level=1)
    for volume in c: ...                       # every time step in order

    volreel.encode(frames, "out.vreel", psnr=50)   # frames: [t, z, y, x] or an iterable of [z, y, x]
    volreel.train(frames, "dictionary.bin", atoms=256)
    volreel.psnr(original, decoded), volreel.ssim(original, decoded)

Errors are volreel.FormatError (a damaged or unexpected container) and volreel.InputError (bad
input data or options), both ValueErrors carrying the library's message; volreel.NetworkError, a
FormatError and a ConnectionError, when a container over HTTP cannot be read (no connection, a
timeout, an HTTP error status); IndexError for a time step or level out of range.
"""

from __future__ import annotations

import os
from typing import Iterator, Optional, Union

from ._volreel import (  # noqa: F401  (re-exported)
    FormatError,
    InputError,
    NetworkError,
    __version__,
    encode,
    psnr,
    ssim,
    train,
)
from ._volreel import Container as _Container

__all__ = [
    "Container",
    "FormatError",
    "InputError",
    "NetworkError",
    "encode",
    "open",
    "psnr",
    "ssim",
    "train",
    "__version__",
]


class Container(_Container):
    """A NAME.vreel container: its time steps as numpy arrays [z, y, x].

    c[t] is c.frame(t) (negative t counts from the end); len(c) is the number of time steps;
    iterating gives every time step in order, decoded one at a time. close(), or the end of a
    `with` block, lets go of its files or connections.
    """

    def __len__(self) -> int:
        return self.frames

    def __getitem__(self, t: int):
        if isinstance(t, slice):
            return [self.frame(i) for i in range(*t.indices(self.frames))]
        return self.frame(t)

    def __iter__(self) -> Iterator:
        for t in range(self.frames):
            yield self.frame(t)

    @property
    def shape(self) -> tuple:
        """(frames, z, y, x): the shape of all time steps stacked."""
        x, y, z = self.dims
        return (self.frames, z, y, x)

    def __enter__(self) -> "Container":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        x, y, z = self.dims
        return (f"volreel.Container({self.location!r}: {x}x{y}x{z} x {self.frames} frames, "
                f"{self.levels} levels, {self.bps:.3f} bps)")


def open(  # noqa: A001  (volreel.open)
    location: Union[str, os.PathLike],
    *,
    tries: int = 4,
    stall_timeout: float = 20.0,
    connections: int = 4,
    cache: Optional[Union[str, os.PathLike]] = None,
    cache_size: str = "2G",
    ca_file: Optional[Union[str, os.PathLike]] = None,
) -> Container:
    """Opens a NAME.vreel folder or an http(s):// URL of one.

    The keywords apply to a URL (as `volreel play URL`'s options of the same names):
    tries: how many times a read of the manifest, dictionary or a frame index is tried when it
        fails in a way that may pass (timeout, refused or reset connection, HTTP 5xx), 1..20;
    stall_timeout: seconds without a byte before a request is given up;
    connections: HTTP connections to the server at most;
    cache: a folder that keeps what arrives, so that the next run starts warm, of at most
        cache_size (e.g. "2G", "500M");
    ca_file: a PEM file of certificate authorities to trust instead of the system's.
    Ctrl-C (KeyboardInterrupt) ends a wait for the server.
    """
    return Container(location, tries=tries, stall_timeout=stall_timeout,
                     connections=connections, cache=cache, cache_size=cache_size,
                     ca_file=ca_file)
