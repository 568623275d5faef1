"""The state and scratch of the compiled loop as numba struct references.

The driver keeps :class:`~crackbake.simulate.solver.iben.state.State` and
:class:`~crackbake.simulate.solver.iben.state.Work` as named tuples; each compiled entry point
(:func:`.loop.run`, :func:`.update.rebuild`, :func:`.update.requeue_all`,
:func:`.update.update_faces`, :func:`.update.update_nodes`) turns them into the struct
references below (same field names, same arrays: nothing is copied) and every kernel below it
takes those.  Both types and both converters are generated from the class bodies of ``State``
and ``Work`` (their annotations name each field's dtype and rank), so a field is added in one
place.  The field types are fixed (``C``-contiguous arrays of one dtype and rank each), so
every kernel compiles once and its cache is reused across processes; tests/test_iben.py checks
them against a real state.

Why struct references (benchmarks/bench_state.py): the 43-field ``State`` tuple is passed to a
kernel as its flattened members (some 340 values), its struct reference as one pointer; a
kernel taking the tuple compiles about 1.6x slower.  A field read costs the same either way,
and from compiled code LLVM inlines small kernels, so no difference of call cost shows.
What a field read does cost is numba's reference counting of the array it returns: an atomic
increment and decrement per read, which :func:`register_borrowing` removes.
"""

from __future__ import annotations

from typing import get_type_hints

import numpy as np
from numba import from_dtype, njit, types
from numba.core import cgutils, imputils
from numba.core.datamodel import default_manager, models
from numba.core.typing.templates import AttributeTemplate
from numba.experimental import structref

from crackbake.simulate.solver.iben.state import State, Work


def register_borrowing(struct_type: type) -> type:
    """``structref.register``, except that an array field is read as a borrowed view.

    numba's own attribute read returns a new reference: an atomic increment of the array's
    reference count, and an atomic decrement when the local dies.  The kernels read their
    fields at the top of every small kernel, and those are called per node and per face, so
    these pairs were about a fifth of the crack loop's time (perf of the README solve: two
    ``lock`` instructions in ``NRT_incref`` and ``NRT_decref`` took 17 % of the samples).
    Here an array field reads as the same array without its owner (a null meminfo, as for
    ``numba.carray``): reference counting skips it.  That is safe because the struct holds the
    arrays for as long as a kernel runs (the struct is made per entry point call and its fields
    are never reassigned inside the kernels) and no kernel returns a field to Python.  Writes
    (the converters' ``r.field = t.field``) count references as numba's do.
    """
    from numba.core.extending import infer_getattr, lower_getattr_generic, lower_setattr_generic

    default_manager.register(struct_type, models.StructRefModel)

    @infer_getattr
    class _Attribute(AttributeTemplate):
        key = struct_type

        def generic_resolve(self, typ, attr):
            return typ.field_dict.get(attr)

    @lower_getattr_generic(struct_type)
    def _getattr(context, builder, typ, val, attr):
        data = structref._Utils(context, builder, typ).get_data_struct(val)
        value = getattr(data, attr)
        field = typ.field_dict[attr]
        if not isinstance(field, types.Array):
            return imputils.impl_ret_borrowed(context, builder, field, value)
        view = context.make_array(field)(context, builder, value=value)
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return imputils.impl_ret_untracked(context, builder, field, view._getvalue())

    @lower_setattr_generic(struct_type)
    def _setattr(context, builder, sig, args, attr):
        [inst_type, val_type] = sig.args
        [instance, val] = args
        data = structref._Utils(context, builder, inst_type).get_data_struct(instance)
        cast = context.cast(builder, val, val_type, inst_type.field_dict[attr])
        old = getattr(data, attr)
        context.nrt.incref(builder, val_type, cast)
        context.nrt.decref(builder, val_type, old)  # last: the new value may be the old one
        setattr(data, attr, cast)

    return struct_type


@register_borrowing
class StateRef(types.StructRef):
    """numba type of the loop's state (the fields of ``State``)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@register_borrowing
class WorkRef(types.StructRef):
    """numba type of the loop's scratch (the fields of ``Work``)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


def numba_fields(cls: type) -> tuple[tuple[str, types.Type], ...]:
    """``(name, numba type)`` of each field of named tuple ``cls``, in order.

    An ``Annotated[np.ndarray, dtype, ndim]`` field is a ``C``-contiguous array of that dtype
    and rank, a ``float`` field a float64, an ``int`` field an int64.
    """
    fields = []
    for name, hint in get_type_hints(cls, include_extras=True).items():
        if hint is float:
            fields.append((name, types.float64))
        elif hint is int:
            fields.append((name, types.int64))
        else:
            dtype, ndim = hint.__metadata__
            fields.append((name, types.Array(from_dtype(np.dtype(dtype)), ndim, "C")))
    return tuple(fields)


def _converter(name: str, struct_type: types.StructRef, fields) -> object:
    """A compiled function ``name(t)``: the struct reference of type ``struct_type`` holding
    the fields of named tuple ``t`` (the same arrays, each field assigned by name).

    numba cannot assign a field named by a variable, so the body is generated; it is compiled
    with this file as its source so that numba's on-disk cache finds it (a change of the
    fields changes the argument type, so a stale entry is never loaded).
    """
    body = "".join(f"    r.{field} = t.{field}\n" for field, _ in fields)
    source = f"def {name}(t):\n    r = structref.new(struct_type)\n{body}    return r\n"
    scope = {"__name__": __name__, "structref": structref, "struct_type": struct_type}
    exec(compile(source, __file__, "exec"), scope)
    func = scope[name]
    func.__doc__ = "The struct reference of named tuple ``t``, sharing its arrays."
    return njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)(func)


STATE_FIELDS = numba_fields(State)
WORK_FIELDS = numba_fields(Work)
STATE_T = StateRef(list(STATE_FIELDS))
WORK_T = WorkRef(list(WORK_FIELDS))

state_ref = _converter("state_ref", STATE_T, STATE_FIELDS)
"""The struct reference (``STATE_T``) of a ``State``, sharing its arrays."""
work_ref = _converter("work_ref", WORK_T, WORK_FIELDS)
"""The struct reference (``WORK_T``) of a ``Work``, sharing its arrays."""
