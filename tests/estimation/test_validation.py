"""The one numeric check (:mod:`estimation.validation`) and the config classes that use it
(issue 20, "numbers and types at entry")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import pytest

from azimut_env import params
from azimut_env.env import AzimutEnv
from azimut_env.task.config import TaskConfig
from estimation import it
from estimation.validation import check_fields, check_finite, check_int, check_real, check_seed, real_scalar

REAL = [(1, 1.0), (2.5, 2.5), (np.float32(0.5), 0.5), (np.int64(3), 3.0), (np.uint8(7), 7.0),
        (np.float16(2), 2.0), (np.longdouble(0.25), 0.25), (np.array(1.5), 1.5), (np.array(4), 4.0),
        (Fraction(1, 4), 0.25)]
NOT_A_NUMBER = [True, False, np.True_, np.bool_(False), np.array(True), "1.0", b"1", 1j, np.complex128(1),
                np.array(1 + 0j), np.array("1"), None, [1.0], (1.0,), np.array([1.0]), object()]


@pytest.mark.parametrize("value, want", REAL)
def test_real_scalar_accepts_every_real_kind_as_float(value, want):
    got = real_scalar("x", value)
    assert type(got) is float and got == want


@pytest.mark.parametrize("value", NOT_A_NUMBER, ids=repr)
def test_real_scalar_refuses_bools_strings_complex_and_arrays_naming_the_field(value):
    with pytest.raises(TypeError, match="^the_field must be a real number"):
        real_scalar("the_field", value)


@pytest.mark.parametrize("value", [10**400, -10**400, 10**309])
def test_integers_beyond_the_float_range_are_not_finite(value):
    with pytest.raises(ValueError, match=r"the_field must be finite, got an integer of \d+ digits"):
        check_finite("the_field", value)
    assert check_real("x", 10**308) == 1e308  # still in range


def test_check_int_kinds():
    assert check_int("n", np.array(3)) == 3 and type(check_int("n", np.int16(3))) is int
    assert check_int("n", 4.0) == 4 and check_int("n", 10**400) == 10**400  # ints have no range of their own
    for bad in (True, np.True_, "3", 3j, np.array([3])):
        with pytest.raises(TypeError, match="^n must be an integer"):
            check_int("n", bad)
    with pytest.raises(ValueError, match="n must be <= 10"):
        check_int("n", 10**400, max_value=10)
    with pytest.raises(ValueError, match="n must be an integer"):
        check_int("n", 2.5)
    assert check_seed("seed", np.array(5)) == 5
    with pytest.raises(TypeError):
        check_seed("seed", 5.0)


@pytest.mark.parametrize("value", [True, np.True_, np.array(2.0), np.int64(3), np.float32(0.5), 2])
def test_parameter_dataclasses_store_canonical_floats(value):
    """``True``, ``np.True_`` and 0-d arrays were stored as they are by the parameter dataclasses."""
    if isinstance(value, (bool, np.bool_)):
        with pytest.raises(TypeError, match="ChassisParams.mass must be a real number"):
            params.ChassisParams(mass=value)
        return
    got = params.ChassisParams(mass=value).mass
    assert type(got) is float and got == float(np.asarray(value))


@pytest.mark.parametrize("make", [lambda v: params.ChassisParams(mass=v), lambda v: params.TireParams(friction=v),
                                  lambda v: TaskConfig(control_period=v), lambda v: it.ITParams(eps_delta=v),
                                  lambda v: AzimutEnv(noise_scale=v)])
@pytest.mark.parametrize("value, error", [(10**400, ValueError), ("0.5", TypeError), (0.5j, TypeError)])
def test_config_fields_refuse_big_ints_strings_complex_naming_the_field(make, value, error):
    """10**400 raised OverflowError from the shared checks; strings and complex numbers raised
    errors that did not name the field."""
    with pytest.raises(error) as info:
        make(value)
    assert any(name in str(info.value) for name in ("mass", "friction", "control_period", "eps_delta", "noise_scale"))


def test_int_fields_store_int_and_refuse_bool():
    assert type(params.SensorParams(wheel_cpr=np.int64(1024)).wheel_cpr) is int
    assert type(it.ITParams(max_iter=np.array(12)).max_iter) is int
    with pytest.raises(TypeError, match="SensorParams.wheel_cpr"):
        params.SensorParams(wheel_cpr=True)


@pytest.mark.parametrize("value", [0, False, "", [], 0.0])
def test_falsy_localisation_is_refused_not_replaced_by_the_default(value):
    with pytest.raises(TypeError, match="localisation"):
        AzimutEnv(localisation=value)
    assert AzimutEnv(localisation=None).config.localisation == TaskConfig().localisation


def test_check_fields_by_annotation():
    @dataclass(frozen=True)
    class Conf:
        a: float = 1.0
        b: int = 2
        c: bool = False
        d: float | None = None
        e: str = "x"
        f: tuple[float, ...] = ()  # left to the class

        def __post_init__(self):
            check_fields(self)

    c = Conf(a=np.array(2), b=np.float64(3.0), c=np.True_, d=np.int8(4), f=("y",))
    assert (type(c.a), type(c.b), type(c.c), type(c.d)) == (float, int, bool, float)
    assert math.isinf(Conf(a=math.inf).a)  # inf is the class's to refuse (some fields mean "none" by it)
    for kwargs, error, name in ((dict(a=math.nan), ValueError, "Conf.a"), (dict(b=True), TypeError, "Conf.b"),
                                (dict(c=1), TypeError, "Conf.c"), (dict(e=1), TypeError, "Conf.e"),
                                (dict(d="1"), TypeError, "Conf.d")):
        with pytest.raises(error, match=name):
            Conf(**kwargs)
