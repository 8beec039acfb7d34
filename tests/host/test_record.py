"""wavemesh.record against dataclasses: the same class body as a ``@record`` and as a ``@dataclass`` behave
the same (construction, defaults, factories, keyword-only, __post_init__, repr, equality, hashing, eq=False,
frozen assignment, and dataclasses.fields / replace / asdict / is_dataclass on the record)."""

from __future__ import annotations

import dataclasses
import pickle

import pytest
from wavemesh.record import record


def pair(**options):
    """The same body under @dataclass(**options) and @record(**options)."""

    def body():
        class C:
            a: int
            b: str = "x"
            c: list = dataclasses.field(default_factory=list)

            def total(self):
                return self.a + len(self.c)

        return C

    return dataclasses.dataclass(**options)(body()), record(**options)(body())


def same(fn, *args, **kw):
    """fn(*args, **kw)'s result, or its exception's type and message."""
    try:
        return ("ok", fn(*args, **kw))
    except Exception as e:  # noqa: BLE001 - the comparison is of what each raises
        return (type(e), str(e).split("__init__()")[-1])


@pytest.mark.parametrize("options", [{}, {"frozen": True}, {"kw_only": True}])
def test_behaves_as_dataclass(options):
    d, r = pair(**options)
    calls = [((1,), {}), ((1, "y"), {}), ((1, "y", [2]), {}), ((), {"a": 3, "c": [1, 2]}), ((), {}),
             ((1, 2, 3, 4), {}), ((1,), {"a": 2}), ((), {"a": 1, "z": 2})]
    for args, kw in calls:
        a, b = same(d, *args, **kw), same(r, *args, **kw)
        assert a[0] == b[0], (options, args, kw, a, b)
        if a[0] == "ok":
            x, y = a[1], b[1]
            assert repr(x).replace(d.__qualname__, "C") == repr(y).replace(r.__qualname__, "C")
            assert dataclasses.asdict(x) == dataclasses.asdict(y)
            assert y.total() == x.total()
            assert [f.name for f in dataclasses.fields(x)] == [f.name for f in dataclasses.fields(y)]
            assert dataclasses.is_dataclass(y) and dataclasses.is_dataclass(r)
            z = dataclasses.replace(y, b="q")
            assert type(z) is r and z.b == "q" and z.a == y.a and z.c == y.c
            assert y == r(**dataclasses.asdict(y)) and y != z and (y == x) is False
            assert same(setattr, x, "a", 9)[0] == same(setattr, y, "a", 9)[0]
            assert same(hash, x)[0] == same(hash, y)[0]
            if same(hash, x)[0] == "ok":
                assert hash(y) == hash(r(**dataclasses.asdict(y)))
    # a factory's value is new for each instance
    if not options.get("kw_only"):
        assert r(1).c is not r(1).c


@pytest.mark.parametrize("options", [{"eq": False}, {"frozen": True, "eq": False}])
def test_without_eq_identity_as_dataclass(options):
    """eq=False: equality and hashing by identity, as dataclasses' (a frozen one still refuses assignment)."""
    d, r = pair(**options)
    for cls in (d, r):
        x, y = cls(1, "y", [2]), cls(1, "y", [2])
        assert x == x and x != y and hash(x) == object.__hash__(x) and len({x, y}) == 2
        assert repr(x).endswith("(a=1, b='y', c=[2])")
    assert same(setattr, d(1), "a", 9)[0] == same(setattr, r(1), "a", 9)[0]


def test_inheritance_post_init_and_pickle():
    @record(kw_only=True)
    class Base:
        a: int
        b: int = 2

    @record(kw_only=True)
    class Child(Base):
        c: int

        def __post_init__(self):
            self.total = self.a + self.b + self.c

    x = Child(a=1, c=3)
    assert (x.a, x.b, x.c, x.total) == (1, 2, 3, 6)
    assert [f.name for f in dataclasses.fields(Child)] == ["a", "b", "c"]
    with pytest.raises(TypeError):
        Child(1, 2, 3)  # keyword-only
    with pytest.raises(TypeError):
        Child(a=1)  # c missing


@record(frozen=True)
class Point:
    x: int
    y: int = 0


def test_frozen_pickles_and_refuses_assignment():
    p = Point(1, 2)
    assert pickle.loads(pickle.dumps(p)) == p
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.x = 3
    with pytest.raises(dataclasses.FrozenInstanceError):
        del p.y
    assert {p: 1}[Point(1, 2)] == 1 and hash(p) == hash(dataclasses.dataclass(frozen=True)(type("P", (), {
        "__annotations__": {"x": "int", "y": "int"}, "y": 0}))(1, 2))


def test_classvar_refused():
    with pytest.raises(TypeError, match="ClassVar"):
        @record
        class Bad:
            n: ClassVar[int] = 1  # noqa: F821 - a string annotation, never evaluated


def test_by_position_runs_post_init_and_factories():
    """A record built by position alone (the one-pass path of __init__): its defaults, a new factory value
    each time, __post_init__ run, and a missing field a TypeError, as dataclasses."""

    def body():
        class C:
            a: int
            b: int = 2
            c: list = dataclasses.field(default_factory=list)

            def __post_init__(self):
                self.total = self.a + self.b + len(self.c)

        return C

    d, r = dataclasses.dataclass(body()), record(body())
    for args in [(1,), (1, 5), (1, 5, [7, 8]), ()]:
        a, b = same(d, *args), same(r, *args)
        assert a[0] == b[0], (args, a, b)
        if a[0] == "ok":
            assert (b[1].a, b[1].b, b[1].c, b[1].total) == (a[1].a, a[1].b, a[1].c, a[1].total)
    assert r(1).c is not r(1).c
