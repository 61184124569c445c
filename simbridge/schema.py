"""Typed settings records: declared fields, converted and checked when a record is made.

A :class:`Record` subclass declares its fields as annotated class attributes; a field's
:func:`setting` adds its default, bounds, description and an optional ``before`` converter::

    class RobotParams(Record):
        mass: float = setting(default=1.5, gt=0, le=1000, description="chassis mass, kg")

Records are keyword-only: ``RobotParams(mass=2)``, or :meth:`Record.parse` for a mapping (a
YAML document, a JSON object). Values are converted by their annotation, in the lax way files
and environment variables need, and every refusal names the field path and the reason in one
:class:`ValidationError`, e.g. ``robot.wheel_radius: must be greater than 0 (got -1)``:

- ``float``: an int, a float or a numeric string; always finite (NaN and infinities are refused
  everywhere: no setting needs them); ``int``: an int, a float without fraction or an integer
  string. A bool is not a number (``rays: yes`` is a mistake, not 1).
- ``bool``: a bool, 0 or 1, or ``true/false``, ``yes/no``, ``on/off``, ``t/f``, ``y/n``, ``1/0``
  in any case (environment variables are text).
- ``str``: a string only; ``Literal[...]``: one of its values.
- ``tuple[X, Y]``, ``tuple[X, ...]``, ``list[X]``: a list or a tuple; ``dict[K, V]``: a mapping;
  ``X | None``; a nested record: a mapping of its keys (or a record of that class).
- ``Annotated[X, Bounds(...)]``: a reusable type with bounds (a port, a positive count).

Unknown keys are refused; required fields (no default) must be given; :meth:`Record.check`
holds relations between fields and runs after construction and after every assignment. A record
declared ``class S(Record, frozen=True)`` refuses assignment; the others validate it.
"""

from __future__ import annotations

import inspect
import math
import operator
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Literal, TypeVar, Union, dataclass_transform

from simbridge.errors import ConfigError


__all__ = ["MISSING", "Bounds", "Record", "Setting", "ValidationError", "converter", "setting"]

R = TypeVar("R", bound="Record")


class _Missing:
    def __repr__(self) -> str:
        return "MISSING"


#: No default: the field must be given.
MISSING: Any = _Missing()


def _join(key: str, path: str) -> str:
    if not path:
        return key
    if not key:
        return path
    return f"{key}{path}" if path.startswith("[") else f"{key}.{path}"


class ValidationError(ConfigError, ValueError):
    """Values refused by a record or a converter: each with its field path and the reason.

    ``str(err)`` is every refusal, ``path: reason``, joined by ``"; "`` (a refusal of the whole
    record, a relation between fields, has no path). A ``ValueError`` (parameter services
    catch those) and a :class:`~simbridge.errors.ConfigError`.

    Attributes:
        errors: ``(path, reason)`` pairs: ``("robot.mass", "must be greater than 0 (got -1)")``,
            ``("walls[1]", ...)``; the path is ``""`` for the record as a whole.
    """

    def __init__(self, errors: Sequence[tuple[str, str]]) -> None:
        self.errors = list(errors)
        super().__init__(self.describe())

    def __reduce__(self) -> tuple[type[ValidationError], tuple[list[tuple[str, str]]]]:
        """Pickle by the refusals (an exception pickles its message otherwise, not ``errors``)."""
        return type(self), (self.errors,)

    @classmethod
    def one(cls, reason: str, path: str = "") -> ValidationError:
        """Return an error of one refusal."""
        return cls([(path, reason)])

    def describe(self, name: Callable[[str], str] = str) -> str:
        """Return the refusals as one line, each path shown as ``name(path)``."""
        return "; ".join(f"{name(p)}: {r}" if p else r for p, r in self.errors)

    def within(self, key: str) -> ValidationError:
        """Return this error with every path under ``key`` (``mass`` -> ``robot.mass``)."""
        return ValidationError([(_join(key, p), r) for p, r in self.errors])


class Bounds:
    """Bounds of a value: numbers (``gt``, ``ge``, ``lt``, ``le``), lengths (strings, lists).

    Used by :func:`setting` and, for a reusable type, in ``Annotated[int, Bounds(ge=0)]``.
    """

    __slots__ = ("ge", "gt", "le", "lt", "max_length", "min_length")

    def __init__(
        self,
        *,
        gt: float | None = None,
        ge: float | None = None,
        lt: float | None = None,
        le: float | None = None,
        min_length: int | None = None,
        max_length: int | None = None,
    ) -> None:
        self.gt, self.ge, self.lt, self.le = gt, ge, lt, le
        self.min_length, self.max_length = min_length, max_length

    def __bool__(self) -> bool:
        return any(getattr(self, name) is not None for name in self.__slots__)

    def __repr__(self) -> str:
        shown = [
            f"{n}={getattr(self, n)!r}" for n in self.__slots__ if getattr(self, n) is not None
        ]
        return f"Bounds({', '.join(shown)})"

    def text(self) -> str:
        """The numeric bounds in words for a person: ``> 0 and <= 1000`` (``""``: none)."""
        parts = [
            f"{sign} {value}"
            for sign, value in ((">", self.gt), (">=", self.ge), ("<", self.lt), ("<=", self.le))
            if value is not None
        ]
        return " and ".join(parts)

    def check(self, value: Any, raw: Any) -> None:
        """Raise :class:`ValidationError` if ``value`` (converted from ``raw``) is out of bounds."""
        got = f" (got {raw!r})"
        if isinstance(value, int | float) and not isinstance(value, bool):
            if self.gt is not None and not value > self.gt:
                raise ValidationError.one(f"must be greater than {self.gt}{got}")
            if self.ge is not None and not value >= self.ge:
                raise ValidationError.one(f"must be greater than or equal to {self.ge}{got}")
            if self.lt is not None and not value < self.lt:
                raise ValidationError.one(f"must be less than {self.lt}{got}")
            if self.le is not None and not value <= self.le:
                raise ValidationError.one(f"must be less than or equal to {self.le}{got}")
        elif isinstance(value, str | list | tuple | dict):
            unit = "characters" if isinstance(value, str) else "items"
            if self.min_length is not None and len(value) < self.min_length:
                text = "must not be empty" if self.min_length == 1 else ""
                raise ValidationError.one(
                    (text or f"must have at least {self.min_length} {unit}") + got
                )
            if self.max_length is not None and len(value) > self.max_length:
                raise ValidationError.one(
                    f"must have at most {self.max_length} {unit} (got {len(value)})"
                )


class Setting:
    """One declared field of a record: default, bounds, description, ``before`` converter.

    Made by :func:`setting`; read with :meth:`Record.settings`. ``kind`` is the field's
    annotation once the record class has been used (resolved then).
    """

    __slots__ = ("before", "bounds", "convert", "default", "default_factory", "description", "kind")

    def __init__(
        self,
        default: Any = MISSING,
        default_factory: Callable[[], Any] | None = None,
        bounds: Bounds | None = None,
        description: str = "",
        before: Callable[[Any], Any] | None = None,
    ) -> None:
        self.default = default
        self.default_factory = default_factory
        self.bounds = bounds or Bounds()
        self.description = description
        self.before = before
        self.kind: Any = None
        self.convert: Callable[[Any], Any] | None = None

    @property
    def required(self) -> bool:
        """Whether the field has no default."""
        return self.default is MISSING and self.default_factory is None

    def make_default(self) -> Any:
        """Return a fresh default value."""
        if self.default_factory is not None:
            return self.default_factory()
        return self.default


def setting(
    *,
    default: Any = MISSING,
    default_factory: Callable[[], Any] | None = None,
    gt: float | None = None,
    ge: float | None = None,
    lt: float | None = None,
    le: float | None = None,
    min_length: int | None = None,
    max_length: int | None = None,
    description: str = "",
    before: Callable[[Any], Any] | None = None,
) -> Any:
    """Declare a field of a :class:`Record` (the value of its class attribute).

    Args:
        default: its value when not given (immutable; else use ``default_factory``).
        default_factory: makes its value when not given (lists, records).
        gt: the number must be greater than this.
        ge: the number must be greater than or equal to this.
        lt: the number must be less than this.
        le: the number must be less than or equal to this.
        min_length: the string or list must have at least this many characters or items.
        max_length: the string or list must have at most this many.
        description: one line for people: parameter descriptions, ``ros2 param describe``.
        before: called with the given value before it is converted by the annotation; returns
            the value to convert or raises ``ValueError`` (or :class:`ValidationError`) saying
            why (e.g. ``has 3 numbers, expected [x1, y1, x2, y2]``, shown after the key:
            ``walls[1]: has 3 numbers...``).
    """
    bounds = Bounds(gt=gt, ge=ge, lt=lt, le=le, min_length=min_length, max_length=max_length)
    return Setting(default, default_factory, bounds, description, before)


# -- converters: one per annotation, built once per field ---------------------------------------

_TRUE = frozenset({"1", "on", "t", "true", "y", "yes"})
_FALSE = frozenset({"0", "off", "f", "false", "n", "no"})


def _is_bool(value: Any) -> bool:
    """Whether ``value`` is a boolean: Python's or numpy's (``numpy.bool_``)."""
    return isinstance(value, bool) or getattr(getattr(value, "dtype", None), "kind", "") == "b"


def _to_float(value: Any) -> float:
    if _is_bool(value):
        raise ValidationError.one(f"must be a number, not a boolean (got {value!r})")
    try:
        if isinstance(value, str):
            out = float(value)
        elif isinstance(value, int | float) or hasattr(type(value), "__float__"):
            out = float(value)  # also numpy's scalars and Decimal
        else:
            raise ValueError
    except (ValueError, TypeError):  # TypeError: e.g. a numpy array of several numbers
        raise ValidationError.one(f"must be a number (got {value!r})") from None
    except OverflowError:  # an int past float range
        out = math.inf
    if not math.isfinite(out):
        raise ValidationError.one(f"must be a finite number (got {value!r})")
    return out


def _to_int(value: Any) -> int:
    if _is_bool(value):
        raise ValidationError.one(f"must be an integer, not a boolean (got {value!r})")
    if isinstance(value, int):
        return value
    if hasattr(type(value), "__index__"):  # numpy's integers
        try:
            return operator.index(value)
        except TypeError:  # e.g. a numpy array of several integers
            raise ValidationError.one(f"must be a valid integer (got {value!r})") from None
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            pass
    if isinstance(value, float | str) or hasattr(type(value), "__float__"):
        try:
            number = float(value)
        except (ValueError, OverflowError):
            number = math.nan
        if math.isfinite(number) and number.is_integer():
            return int(number)
    raise ValidationError.one(f"must be a valid integer (got {value!r})")


def _to_bool(value: Any) -> bool:
    if _is_bool(value):
        return bool(value)
    if isinstance(value, int | float) and value in (0, 1):
        return bool(value)
    if isinstance(value, str):
        if value.lower() in _TRUE:
            return True
        if value.lower() in _FALSE:
            return False
    msg = f"must be a valid boolean: true/false, yes/no, on/off or 1/0 (got {value!r})"
    raise ValidationError.one(msg)


def _to_str(value: Any) -> str:
    if isinstance(value, str):
        return value
    raise ValidationError.one(f"must be a string (got {value!r})")


def _literal(options: tuple[Any, ...]) -> Callable[[Any], Any]:
    shown = [repr(o) for o in options]
    words = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} or {shown[-1]}"

    def convert(value: Any) -> Any:
        for option in options:
            if type(value) is type(option) and value == option:
                return option
        raise ValidationError.one(f"must be {words} (got {value!r})")

    return convert


def _optional(inner: Callable[[Any], Any]) -> Callable[[Any], Any]:
    def convert(value: Any) -> Any:
        return None if value is None else inner(value)

    return convert


def _items(value: Any, what: str) -> Sequence[Any]:
    if isinstance(value, list | tuple):
        return value
    raise ValidationError.one(f"must be {what} (got {value!r})")


def _each(items: Sequence[Any], converters: Sequence[Callable[[Any], Any]]) -> list[Any]:
    out, errors = [], []
    for i, (item, convert) in enumerate(zip(items, converters, strict=True)):
        try:
            out.append(convert(item))
        except ValidationError as err:
            errors += err.within(f"[{i}]").errors
    if errors:
        raise ValidationError(errors)
    return out


def _tuple(args: tuple[Any, ...]) -> Callable[[Any], Any]:
    if len(args) == 2 and args[1] is Ellipsis:
        item = converter(args[0])

        def variadic(value: Any) -> tuple[Any, ...]:
            items = _items(value, "a list")
            return tuple(_each(items, [item] * len(items)))

        return variadic
    converters = [converter(a) for a in args]
    n = len(converters)

    def fixed(value: Any) -> tuple[Any, ...]:
        items = _items(value, f"a list of {n} items")
        if len(items) != n:
            raise ValidationError.one(f"must have {n} items (got {len(items)}: {value!r})")
        return tuple(_each(items, converters))

    return fixed


def _list(arg: Any) -> Callable[[Any], Any]:
    item = converter(arg)

    def convert(value: Any) -> list[Any]:
        items = _items(value, "a list")
        return _each(items, [item] * len(items))

    return convert


def _dict(key_type: Any, value_type: Any) -> Callable[[Any], Any]:
    key, item = converter(key_type), converter(value_type)

    def convert(value: Any) -> dict[Any, Any]:
        if not isinstance(value, Mapping):
            raise ValidationError.one(f"must be a mapping (got {value!r})")
        out, errors = {}, []
        for k, v in value.items():
            try:
                out[key(k)] = item(v)
            except ValidationError as err:
                errors += err.within(f"[{k!r}]").errors
        if errors:
            raise ValidationError(errors)
        return out

    return convert


def _record(cls: type[Record]) -> Callable[[Any], Any]:
    def convert(value: Any) -> Record:
        if isinstance(value, cls):
            return value
        if isinstance(value, Mapping):
            return cls.parse(value)
        raise ValidationError.one(f"must be a mapping of keys (got {value!r})")

    return convert


def _bounded(inner: Callable[[Any], Any], bounds: Bounds) -> Callable[[Any], Any]:
    if not bounds:
        return inner

    def convert(value: Any) -> Any:
        out = inner(value)
        bounds.check(out, value)
        return out

    return convert


_SCALARS: dict[Any, Callable[[Any], Any]] = {
    float: _to_float,
    int: _to_int,
    bool: _to_bool,
    str: _to_str,
}


def converter(kind: Any) -> Callable[[Any], Any]:
    """Return the function that converts and checks a value of the annotation ``kind``.

    The function returns the converted value or raises :class:`ValidationError` (paths
    relative to the value: ``[2]`` for a list's third item).

    Raises:
        TypeError: ``kind`` is an annotation this module does not handle.
    """
    if kind in _SCALARS:
        return _SCALARS[kind]
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin is typing.Annotated:
        bounds = [m for m in kind.__metadata__ if isinstance(m, Bounds)]
        out = converter(args[0])
        for b in bounds:
            out = _bounded(out, b)
        return out
    if origin in (Union, types.UnionType):
        others = [a for a in args if a is not type(None)]
        if len(others) == 1 and len(args) == 2:
            return _optional(converter(others[0]))
    elif origin is Literal:
        return _literal(args)
    elif origin is tuple:
        return _tuple(args)
    elif origin is list:
        return _list(args[0])
    elif origin is dict:
        return _dict(*args)
    elif isinstance(kind, type) and issubclass(kind, Record):
        return _record(kind)
    msg = f"settings cannot hold values of type {kind!r}"
    raise TypeError(msg)


def _field(s: Setting, kind: Any) -> Callable[[Any], Any]:
    convert = _bounded(converter(kind), s.bounds)
    before = s.before
    if before is None:
        return convert

    def with_before(value: Any) -> Any:
        try:
            value = before(value)
        except ValidationError:
            raise
        except ValueError as err:
            raise ValidationError.one(str(err)) from None
        return convert(value)

    return with_before


# -- records ------------------------------------------------------------------------------------


@dataclass_transform(kw_only_default=True, field_specifiers=(setting,))
class Record:
    """Base of the settings records (see the module docstring)."""

    __settings__: ClassVar[dict[str, Setting]] = {}
    __frozen__: ClassVar[bool] = False
    __resolved__: ClassVar[bool] = False

    def __init_subclass__(cls, *, frozen: bool = False, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        found = dict(cls.__settings__)
        for name, annotation in inspect.get_annotations(cls).items():
            if str(annotation).startswith(("ClassVar", "typing.ClassVar")):
                continue
            value = cls.__dict__.get(name, MISSING)
            found[name] = value if isinstance(value, Setting) else Setting(value)
            if name in cls.__dict__:
                delattr(cls, name)
        cls.__settings__ = found
        cls.__frozen__ = frozen
        cls.__resolved__ = False

    @classmethod
    def settings(cls) -> dict[str, Setting]:
        """Return the declared fields by name, in declaration order (base classes first)."""
        if not cls.__dict__.get("__resolved__"):
            hints = typing.get_type_hints(cls, include_extras=True)
            for name, s in cls.__settings__.items():
                if s.convert is None:
                    s.kind = hints[name]
                    s.convert = _field(s, hints[name])
            cls.__resolved__ = True
        return cls.__settings__

    @classmethod
    def parse(cls: type[R], data: Mapping[str, Any]) -> R:
        """Return a record of the keys of ``data`` (a YAML document, a JSON object).

        Raises:
            ValidationError: a key is unknown or missing, or a value is refused.
        """
        if not isinstance(data, Mapping):
            raise ValidationError.one(f"must be a mapping of keys (got {data!r})")
        bad = [k for k in data if not isinstance(k, str)]
        if bad:
            raise ValidationError([(repr(k), "keys must be names (strings)") for k in bad])
        return cls(**data)

    def __init__(self, /, **values: Any) -> None:  # positional-only: a key may be ``self``
        settings = type(self).settings()
        errors = [
            (name, "unknown key (check its spelling and nesting)")
            for name in values
            if name not in settings
        ]
        out: dict[str, Any] = {}
        for name, s in settings.items():
            if name in values:
                try:
                    out[name] = s.convert(values[name])  # type: ignore[misc]  # resolved above
                except ValidationError as err:
                    errors += err.within(name).errors
            elif s.required:
                errors.append((name, "required, but missing"))
            else:
                out[name] = s.make_default()
        if errors:
            raise ValidationError(errors)
        self.__dict__.update(out)
        self.__dict__["_given"] = frozenset(values)
        self._check()

    def _check(self) -> None:
        try:
            self.check()
        except ValidationError:
            raise
        except ValueError as err:
            raise ValidationError.one(str(err)) from None

    def check(self) -> None:
        """Check relations between fields (after construction and every assignment).

        Raises:
            ValueError: the combination is invalid; the text says why.
        """

    @property
    def given(self) -> frozenset[str]:
        """The fields given at construction or assigned since (not left at their default)."""
        given: frozenset[str] = self.__dict__["_given"]
        return given

    def __setattr__(self, name: str, value: Any) -> None:
        cls = type(self)
        settings = cls.settings()
        if name not in settings:
            raise ValidationError.one(f"{cls.__name__} has no setting {name!r}", name)
        if cls.__frozen__:
            raise ValidationError.one("cannot be changed: these settings are frozen", name)
        convert = settings[name].convert
        assert convert is not None
        try:
            new = convert(value)
        except ValidationError as err:
            raise err.within(name) from None
        old, given = self.__dict__[name], self.given
        self.__dict__[name] = new
        self.__dict__["_given"] = given | {name}  # before the check: it may ask what was given
        try:
            self._check()
        except ValidationError:
            self.__dict__[name] = old
            self.__dict__["_given"] = given
            raise

    def __delattr__(self, name: str) -> None:
        raise ValidationError.one("cannot be deleted", name)

    def as_dict(self) -> dict[str, Any]:
        """Return the values by field name; nested records (also in lists) as dicts."""
        return {name: _plain(getattr(self, name)) for name in type(self).settings()}

    def replace(self: R, **changes: Any) -> R:
        """Return a copy with ``changes`` (validated as at construction).

        Raises:
            ValidationError: a change is refused.
        """
        kept = {name: getattr(self, name) for name in self.given}
        return type(self)(**{**kept, **changes})

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        names = type(self).settings()
        return all(getattr(self, n) == getattr(other, n) for n in names)

    __hash__ = None  # type: ignore[assignment]  # mutable (or holding dicts and lists)

    def __repr__(self) -> str:
        shown = ", ".join(f"{n}={getattr(self, n)!r}" for n in type(self).settings())
        return f"{type(self).__name__}({shown})"


def _plain(value: Any) -> Any:
    if isinstance(value, Record):
        return value.as_dict()
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value
