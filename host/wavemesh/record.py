"""``@record``: the value classes of the start-up path (HeightField, Mesh, MeshParams, RefineParams, ...)
without the cost of ``@dataclass`` at import.

``dataclasses.dataclass`` writes each class's ``__init__``, ``__repr__``, ``__eq__`` (and a frozen
class's ``__setattr__``, ``__delattr__``, ``__hash__``) as source text and compiles it: about 6 M
instructions a class, 125 M for the 21 classes `wavemesh mesh` imports, most of wavemesh's start-up
(bench/process_instructions.py counts it); the 15 of a tiled run's wavemesh.tiles another 50 M
(`import numpy, wavemesh.cli, wavemesh.tiles` under callgrind, over `import numpy`: 163 M as
dataclasses, 113 M).  ``@record`` takes the same class body (annotated fields, defaults,
``dataclasses.field(default_factory=...)``, ``__post_init__``) and the options used here (``frozen``,
``kw_only``, ``eq=False``), and gives the class generic methods made once in this module, so a class
costs only the reading of its annotations.  The methods behave as dataclasses' do: the same positional and
keyword arguments, ``repr``, equality over the fields (same class only), hashing of a frozen record,
``dataclasses.FrozenInstanceError`` on assignment to a frozen one.

``dataclasses.fields``, ``replace``, ``asdict`` and ``is_dataclass`` work on a record: it carries the
``__dataclass_fields__`` table they read (``dataclasses.Field`` objects, marked as plain fields;
tests/host/test_record.py checks those functions against a real dataclass, so a Python whose dataclasses
read the table differently fails there).  Field annotations are kept as written (strings: every module
here has ``from __future__ import annotations``); ``ClassVar`` and ``InitVar`` fields are not supported
(refused at class creation).
"""

from __future__ import annotations

import dataclasses

_MISSING = dataclasses.MISSING


def record(cls=None, /, *, frozen: bool = False, kw_only: bool = False, eq: bool = True):
    """The class decorator: ``@record``, ``@record(frozen=True)``, ``@record(kw_only=True)``; ``eq=False``:
    no ``__eq__`` (nor a hash of the fields): instances compare and hash by identity, as dataclasses'."""
    if cls is None:
        return lambda c: _make(c, frozen, kw_only, eq)
    return _make(cls, frozen, kw_only, eq)


def _make(cls, frozen: bool, kw_only: bool, eq: bool = True):
    table: dict[str, dataclasses.Field] = {}
    for base in reversed(cls.__mro__[1:]):
        table.update(getattr(base, "__dataclass_fields__", {}))
    for name, kind in cls.__dict__.get("__annotations__", {}).items():
        text = kind if isinstance(kind, str) else getattr(kind, "__name__", "")
        if text.startswith(("ClassVar", "typing.ClassVar", "InitVar", "dataclasses.InitVar")):
            raise TypeError(f"@record {cls.__qualname__}.{name}: ClassVar / InitVar fields are not supported")
        value = cls.__dict__.get(name, _MISSING)
        if isinstance(value, dataclasses.Field):
            f = value
            if f.default is _MISSING:
                delattr(cls, name)  # as dataclasses: no class attribute for a field without a plain default
            else:
                setattr(cls, name, f.default)
        else:
            f = dataclasses.field(default=value)
        f.name, f.type, f._field_type = name, kind, dataclasses._FIELD
        f.kw_only = kw_only
        table[name] = f
    cls.__dataclass_fields__ = table
    names = tuple(table)
    positional = tuple(n for n, f in table.items() if not f.kw_only)
    defaults = {n: f.default for n, f in table.items() if f.default is not _MISSING}
    factories = {n: f.default_factory for n, f in table.items() if f.default_factory is not _MISSING}
    post_init = getattr(cls, "__post_init__", None) is not None
    qualname = cls.__qualname__
    setter = object.__setattr__

    def default(self, n):  # a field not given: its default, its factory's value, or the error
        if n in defaults:
            setter(self, n, defaults[n])
        elif n in factories:
            setter(self, n, factories[n]())
        else:
            raise TypeError(f"{qualname}.__init__() missing required argument: {n!r}")

    def __init__(self, *args, **kwargs):
        if not kwargs and len(args) <= len(names) == len(positional):  # by position alone: in one pass
            for n, v in zip(names, args, strict=False):  # the first len(args) fields
                setter(self, n, v)
            for n in names[len(args):]:
                default(self, n)
            if post_init:
                self.__post_init__()
            return
        if len(args) > len(positional):
            raise TypeError(f"{qualname}.__init__() takes {len(positional) + 1} positional arguments but "
                            f"{len(args) + 1} were given")
        values = dict(zip(positional, args, strict=False))  # fewer than all: the rest by keyword
        for k in kwargs:
            if k not in table:
                raise TypeError(f"{qualname}.__init__() got an unexpected keyword argument {k!r}")
            if k in values:
                raise TypeError(f"{qualname}.__init__() got multiple values for argument {k!r}")
        values.update(kwargs)
        for n in names:
            if n in values:
                setter(self, n, values[n])
            else:
                default(self, n)
        if post_init:
            self.__post_init__()

    def __repr__(self):
        return f"{type(self).__qualname__}({', '.join(f'{n}={getattr(self, n)!r}' for n in names)})"

    def __eq__(self, other):
        if other.__class__ is not self.__class__:
            return NotImplemented
        return tuple(getattr(self, n) for n in names) == tuple(getattr(other, n) for n in names)

    methods = {"__init__": __init__, "__repr__": __repr__}
    if eq:
        methods["__eq__"] = __eq__
    if frozen:
        def __setattr__(self, name, value):
            raise dataclasses.FrozenInstanceError(f"cannot assign to field {name!r}")

        def __delattr__(self, name):
            raise dataclasses.FrozenInstanceError(f"cannot delete field {name!r}")

        def __hash__(self):
            return hash(tuple(getattr(self, n) for n in names))

        methods.update(__setattr__=__setattr__, __delattr__=__delattr__)
        if eq:
            methods["__hash__"] = __hash__
    elif eq:
        methods["__hash__"] = None  # as dataclasses: a mutable class with __eq__ is unhashable
    for name, fn in methods.items():
        if name in cls.__dict__:
            continue  # the class's own method stands, as with dataclasses
        if fn is not None:
            fn.__qualname__ = f"{qualname}.{name}"
        setattr(cls, name, fn)
    return cls
