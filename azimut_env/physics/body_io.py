"""Batched reads and writes of the robots' chassis bodies in a pymunk Space (``pymunk.batch``).

:class:`BodyIO` moves every dynamic body's pose and velocity (the columns
:class:`~azimut_env.physics.layout.CS`) between the Space and one NumPy array, and the force and
torque (:class:`~azimut_env.physics.layout.FT`) the other way, one call each for all bodies.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pymunk
import pymunk.batch as pb

from azimut_env.physics.layout import CS, FT

__all__ = ["BodyIO"]

_STATE_FIELDS = (pb.BodyFields.POSITION | pb.BodyFields.ANGLE | pb.BodyFields.VELOCITY
                 | pb.BodyFields.ANGULAR_VELOCITY)
_FORCE_FIELDS = pb.BodyFields.FORCE | pb.BodyFields.TORQUE


class BodyIO:
    """The state rows of a Space's bodies: ``state`` (rows, len(CS)) and ``forces`` (rows, len(FT)).

    ``bodies`` (robot i's chassis at index i) must be the first bodies ``pymunk.batch`` lists, in
    order (checked: ``RuntimeError`` otherwise); rows beyond them (pymunk's static body, once it
    holds obstacle shapes) are read and written back unchanged. Not picklable: build a new one
    for an unpickled Space.
    """

    def __init__(self, space: pymunk.Space, bodies: Sequence[pymunk.Body]) -> None:
        self._space = space
        self._get_buf = pb.Buffer()
        pb.get_space_bodies(space, pb.BodyFields.BODY_ID, self._get_buf)
        ids = list(memoryview(self._get_buf.int_buf()).cast("P"))
        ours = [b.id for b in bodies]
        if ids[: len(ours)] != ours:
            raise RuntimeError("pymunk.batch does not list the robot bodies first, in creation order")
        self.rows = len(ids)
        #: (rows, len(CS)) pose and velocity in the world: :meth:`read` fills it, :meth:`write` writes it
        self.state = np.zeros((self.rows, len(CS)))
        self._shape = self.state.shape
        self._set_buf = pb.Buffer()
        self._set_buf.set_float_buf(self.state)
        #: (rows, len(FT)) force and torque in the world that :meth:`write_forces` applies
        self.forces = np.zeros((self.rows, len(FT)))
        self._force_buf = pb.Buffer()
        self._force_buf.set_float_buf(self.forces)
        # Fast path: the same C iterators that pymunk.batch.get/set_space_bodies call, with their
        # argument structs built once (saves most of the per-call Python overhead).
        self._fast = None
        ffi, lib = getattr(pb, "ffi", None), getattr(pb, "lib", None)
        if ffi is not None and lib is not None and hasattr(lib, "cpSpaceEachBody"):
            try:
                get_data = ffi.new("pmBatchedData *")
                get_data.fields = _STATE_FIELDS.value
                get_data.floatArray = self._get_buf._float_arr
                get_data.intArray = self._get_buf._int_arr
                set_data = ffi.new("pmBatchedData *")
                set_data.fields = _STATE_FIELDS.value
                set_data.floatArray = self._set_buf._float_arr
                set_data.intArray = self._set_buf._int_arr
                self._fast = (lib, get_data, set_data, ffi.addressof(lib, "pmSpaceBodyGetIteratorFuncBatched"),
                              ffi.addressof(lib, "pmSpaceBodySetIteratorFuncBatched"))
            except (AttributeError, TypeError):  # pymunk.batch changed: use the public functions
                self._fast = None

    def read(self) -> None:
        """Copy every body's (x, y, θ, vx, vy, θ̇) from pymunk into :attr:`state`."""
        buf = self._get_buf
        if self._fast is None:
            buf.clear()
            pb.get_space_bodies(self._space, _STATE_FIELDS, buf)
        else:
            lib, get_data, _, get_fn, _ = self._fast
            buf._float_arr.num = 0
            lib.cpSpaceEachBody(self._space._space, get_fn, get_data)
        self.state[:] = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(self._shape)

    def write(self) -> None:
        """Write :attr:`state` into every body."""
        if self._fast is None:
            pb.set_space_bodies(self._space, _STATE_FIELDS, self._set_buf)
        else:
            lib, _, set_data, _, set_fn = self._fast
            arr = self._set_buf._float_arr
            num = arr.num
            arr.num = 0
            lib.cpSpaceEachBody(self._space._space, set_fn, set_data)
            arr.num = num

    def write_forces(self) -> None:
        """Write :attr:`forces` as every body's force and torque."""
        pb.set_space_bodies(self._space, _FORCE_FIELDS, self._force_buf)
