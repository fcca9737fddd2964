""":meth:`SegmentTracker.step` compiled with numba, when numba is installed (optional).

The numpy path costs a few dozen small numpy calls per vector step, each a few microseconds, so
the tracker adds more time per env-step than the step of a cheap environment. One compiled call
does the same work. It follows the numpy path line by line: the evaluation is
:meth:`TaskModel.reward_and_next_batch` on one row (the same ``weights``, summed in another
order, so results agree up to floating-point rounding), and the shaping is
``SegmentTracker._shape``. ``tests/test_wrappers.py`` checks the two paths agree in
every mode.

On an SB3 vector env the info dicts cost more than that: reading the final observations out of
them and storing three keys into each, in Python, takes longer per sub-env than the whole
compiled step. :func:`step_infos` (``SegmentTracker.step_lift_infos``) does that work in the same
compiled call through CPython's C API (list and dict access, the buffer protocol), as a C
extension would, without a build step. Whatever it does not read (a tuple of infos, a dict
subclass, a final observation of another dtype or layout) stops it before anything changed, and
the Python path takes over.

``pip install swirl-wrappers[numba]`` (sb3-swirl installs it); without numba the tracker uses its
numpy path. Compiled code is cached on disk (numba's ``cache=True``): the first call on a machine
compiles for a few seconds, later processes load it.
"""

from __future__ import annotations

import numpy as np

# Layout of the float64 ``settings`` array that carries the tracker's settings into the step.
SCALE, BONUS, WEIGHT, GAMMA, TIMED = range(5)


def settings(scale: float, bonus: float, weight: float, gamma: float, timed: bool) -> np.ndarray:
    """The ``settings`` argument of :func:`step`."""
    return np.array([scale, bonus, weight, gamma, float(timed)])


def _evaluate(x, index, t, weights, p, timed, t_bounds):  # pragma: no cover - compiled
    """``R_index(x)`` and ``M(x, t, index)`` for one state (one row of the batched product)."""
    n_in = weights.shape[1] - 1
    base = index * 2 * p
    # Rows base .. base + p - 1 give the reward, the next p the region distance: two loops,
    # not one with a branch per row.
    reward = 0.0
    for c in range(base, base + p):
        z = weights[c, n_in]
        for k in range(n_in):
            z += x[k] * weights[c, k]
        reward -= z * z
    dist = 0.0
    for c in range(base + p, base + 2 * p):
        z = weights[c, n_in]
        for k in range(n_in):
            z += x[k] * weights[c, k]
        dist += z * z
    if dist <= 1.0 and (not timed or (t_bounds[0, index] <= t and t <= t_bounds[1, index])):
        return reward, index + 1
    return reward, index


def _potential(x, before, reward, after, weights, p, t_bounds):  # pragma: no cover - compiled
    """``Phi(x, after)`` given ``reward = R_before(x)`` (re-evaluated if the index moved).

    The formula is :func:`swirl_wrappers.progress_potential`'s, on one state.
    """
    if after != before:
        reward = _evaluate(x, after, 0, weights, p, False, t_bounds)[0]
    return after + 1.0 / (1.0 - min(reward, 0.0))


def _lift_row(obs, index, out):  # pragma: no cover - compiled
    """Write ``obs`` (1-D) followed by the one-hot of ``index`` into ``out``."""
    d = len(obs)
    for k in range(d):
        out[k] = obs[k]
    for k in range(d, len(out)):
        out[k] = 0
    out[d + index] = 1


def _step(
    obs,
    x,
    final_obs,
    final_x,
    restart,
    before,
    start,
    clock,
    weights,
    t_bounds,
    settings,
    task_rewards,
    terminated,
    potential,
    reward,
    reward32,
    index,
    new_potential,
    lifted,
    lifted_final,
):  # pragma: no cover - compiled
    """One tracker step for every row; see ``SegmentTracker.step`` and ``step_lift``.

    ``x`` and ``final_x`` hold the task inputs (their leading columns are read) of the
    observations ``obs`` and of the ``restart`` rows' final observations ``final_obs`` (a linear
    task's are the observations themselves). Writes the rewards into ``reward``
    (and ``reward32``), the new indices into ``index[0]``, the indices the transitions ended
    with into ``index[1]``, the potentials into ``new_potential`` and the lifted observations
    into ``lifted`` and ``lifted_final``; moves ``start`` of the restarted rows to ``clock``.

    Arrays that are not given or not needed are ``None``: ``final_obs`` and ``final_x``
    without final states (the restart rows made no transition), ``restart`` without restarts,
    ``task_rewards`` when their weight is 0, ``terminated``, ``potential`` and
    ``new_potential`` outside ``"potential"`` mode, ``reward32``, ``lifted`` and
    ``lifted_final`` when not asked for. numba compiles each combination separately, without
    the branches it does not need; a ``None`` costs less to pass than an empty array.
    """
    scale, bonus, weight = settings[SCALE], settings[BONUS], settings[WEIGHT]
    gamma, timed = settings[GAMMA], settings[TIMED] != 0.0
    n = len(start)
    n_indices = t_bounds.shape[1]
    p = len(weights) // (2 * n_indices)
    # Bounds are not checked on every access (numba's boundscheck made this step about 15%
    # slower). The Python side checks the shapes of what callers pass; these are what they can
    # reach through the tracker's attributes, and the count of final states. All are checked
    # before anything changes.
    if len(before) != n or (potential is not None and len(potential) != n):
        raise ValueError("index and potential must hold one entry per environment")
    for i in range(n):
        if before[i] < 0 or before[i] >= n_indices:
            raise ValueError("index holds a segment index out of range")
    if final_obs is not None:
        if restart is None or np.count_nonzero(restart) != len(final_obs):
            raise ValueError("final_states must hold one state per restart row")
    xi = np.empty(weights.shape[1] - 1)
    j = 0  # the next row of ``final_obs``
    for i in range(n):
        restarts = False
        if restart is not None:
            restarts = restart[i]
        if restarts and final_obs is None:
            # NEXT_STEP: the row holds a new episode's first state and made no transition.
            reward[i] = 0.0
            if reward32 is not None:
                reward32[i] = 0.0
        else:
            # The transition; at a restart row it ends in the final state of the episode.
            # (A copy: ``final_x`` and ``x`` may differ in dtype or layout.)
            if restarts:
                # final_obs is given here; the test (and the one below) lets numba compile the
                # specialisation where it is None, which never reaches this branch.
                if final_obs is not None:
                    for k in range(len(xi)):
                        xi[k] = final_x[j, k]
            else:
                for k in range(len(xi)):
                    xi[k] = x[i, k]
            b = before[i]
            r, after = _evaluate(xi, b, clock - start[i], weights, p, timed, t_bounds)
            if potential is not None:
                phi = 0.0
                if not terminated[i]:
                    phi = _potential(xi, b, r, after, weights, p, t_bounds)
                r = scale * (gamma * phi - potential[i])
                new_potential[i] = phi
            elif scale != 1.0:
                r = r * scale
            if bonus != 0.0:
                r = r + bonus * (after != b)
            if task_rewards is not None:
                r = r + weight * task_rewards[i]
            reward[i] = r
            if reward32 is not None:
                reward32[i] = r
            index[0, i] = index[1, i] = after
            if not restarts:
                if lifted is not None:
                    _lift_row(obs[i], after, lifted[i])
                continue
            if final_obs is not None:
                if lifted_final is not None:
                    _lift_row(final_obs[j], after, lifted_final[j])
            j += 1
        # A new episode starts at the row's state (index 0 at t = 0, as in reset).
        start[i] = clock
        r, after = _evaluate(x[i], 0, 0, weights, p, timed, t_bounds)
        index[0, i] = after
        if final_obs is None:
            index[1, i] = after
        if potential is not None:
            new_potential[i] = _potential(x[i], 0, r, after, weights, p, t_bounds)
        if lifted is not None:
            _lift_row(obs[i], after, lifted[i])


# The C API calls of :func:`_step_infos`: module-level functions in numba's ``@intrinsic`` form,
# made intrinsics on first use (``__getattr__``). Python objects travel as their addresses
# (``id``, the address in CPython) in int64s; the caller holds every object passed, so they stay
# alive. A call that fails clears the Python error and reports the failure in its result, so the
# kernel can leave the work to Python.


def _list_item(typingctx, lst, i):  # pragma: no cover - compiled
    """``PyList_GetItem(lst, i)``, a borrowed reference; 0 if ``lst`` is no list or too short."""
    from llvmlite import ir
    from numba import types
    from numba.core import cgutils

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        item = pyapi.list_getitem(builder.inttoptr(args[0], pyapi.pyobj), args[1])
        with builder.if_then(cgutils.is_null(builder, item)):
            pyapi.err_clear()
        return builder.ptrtoint(item, ir.IntType(64))

    return types.int64(types.int64, types.int64), codegen


def _type_of(typingctx, obj):  # pragma: no cover - compiled
    """The address of ``type(obj)``."""
    from llvmlite import ir
    from numba import types

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        cls = pyapi.get_type(builder.inttoptr(args[0], pyapi.pyobj))
        return builder.ptrtoint(cls, ir.IntType(64))

    return types.int64(types.int64), codegen


def _hold(typingctx, obj):  # pragma: no cover - compiled
    """``Py_INCREF(obj)``: a borrowed reference outlives what the following calls may run."""
    from numba import types

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        pyapi.incref(builder.inttoptr(args[0], pyapi.pyobj))
        return context.get_dummy_value()

    return types.none(types.int64), codegen


def _release(typingctx, obj):  # pragma: no cover - compiled
    """``Py_DECREF(obj)``, the end of a :func:`_hold`."""
    from numba import types

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        pyapi.decref(builder.inttoptr(args[0], pyapi.pyobj))
        return context.get_dummy_value()

    return types.none(types.int64), codegen


def _dict_get(typingctx, d, key):  # pragma: no cover - compiled
    """``PyDict_GetItem(d, key)``, a borrowed reference; 0 if the key is missing."""
    from llvmlite import ir
    from numba import types

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        value = pyapi.dict_getitem(
            builder.inttoptr(args[0], pyapi.pyobj), builder.inttoptr(args[1], pyapi.pyobj)
        )
        return builder.ptrtoint(value, ir.IntType(64))

    return types.int64(types.int64, types.int64), codegen


def _copy_buffer(typingctx, obj, out, fmt):  # pragma: no cover - compiled
    """Copy ``obj`` into the 1-D array ``out`` through the buffer protocol.

    Only a C-contiguous 1-D buffer of ``len(out)`` items of the one-character format ``fmt``
    (the character code of ``out``'s dtype) is copied; ``False`` otherwise.
    """
    from llvmlite import ir
    from numba import types
    from numba.core import cgutils

    if not (isinstance(out, types.Array) and out.ndim == 1 and out.layout == "C"):
        return None  # memcpy needs a contiguous row
    flags = 0x0038 | 0x0004  # PyBUF_C_CONTIGUOUS | PyBUF_FORMAT

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        i8p, i32, ssize = ir.IntType(8).as_pointer(), ir.IntType(32), pyapi.py_ssize_t
        # CPython's Py_buffer: buf, obj, len, itemsize, readonly, ndim, format, shape,
        # strides, suboffsets, internal.
        ssize_p = ssize.as_pointer()
        py_buffer = ir.LiteralStructType(
            [i8p, i8p, ssize, ssize, i32, i32, i8p, ssize_p, ssize_p, ssize_p, i8p]
        )
        out = context.make_array(signature.args[1])(context, builder, args[1])
        (size,) = cgutils.unpack_tuple(builder, out.shape)
        itemsize = ssize(context.get_abi_sizeof(context.get_data_type(signature.args[1].dtype)))
        view = cgutils.alloca_once(builder, py_buffer)
        get = cgutils.get_or_insert_function(
            builder.module,
            ir.FunctionType(i32, [pyapi.pyobj, py_buffer.as_pointer(), i32]),
            "PyObject_GetBuffer",
        )
        release = cgutils.get_or_insert_function(
            builder.module,
            ir.FunctionType(ir.VoidType(), [py_buffer.as_pointer()]),
            "PyBuffer_Release",
        )

        def field(k):
            return builder.load(builder.gep(view, [i32(0), i32(k)]))

        copied = cgutils.alloca_once_value(builder, cgutils.false_bit)
        status = builder.call(get, [builder.inttoptr(args[0], pyapi.pyobj), view, i32(flags)])
        with builder.if_else(builder.icmp_signed("==", status, i32(0))) as (got, failed):
            with failed:
                pyapi.err_clear()
            with got:
                fmt_chars, shape = field(6), field(7)
                one_dim = builder.and_(
                    builder.icmp_signed("==", field(5), i32(1)),
                    builder.and_(
                        cgutils.is_not_null(builder, fmt_chars), cgutils.is_not_null(builder, shape)
                    ),
                )
                with builder.if_then(one_dim):
                    first = builder.zext(builder.load(fmt_chars), args[2].type)
                    fits = builder.and_(
                        builder.and_(
                            builder.icmp_signed("==", builder.load(shape), size),
                            builder.icmp_signed("==", field(3), itemsize),
                        ),
                        builder.icmp_signed("==", first, args[2]),
                    )
                    with builder.if_then(fits):  # and no second character (no byte order)
                        second = builder.load(builder.gep(fmt_chars, [i32(1)]))
                        with builder.if_then(builder.icmp_signed("==", second, second.type(0))):
                            # len(out) items of out's size, whatever the exporter's len says
                            nbytes = builder.mul(size, itemsize)
                            cgutils.raw_memcpy(
                                builder, builder.bitcast(out.data, i8p), field(0), nbytes, 1
                            )
                            builder.store(cgutils.true_bit, copied)
                builder.call(release, [view])
        return builder.load(copied)

    return types.boolean(types.int64, out, types.int64), codegen


def _set_number(typingctx, d, key, value):  # pragma: no cover - compiled
    """``d[key] = value`` as a Python int (integer ``value``) or float; ``False`` on a failure."""
    from numba import types

    integer = isinstance(value, types.Integer)

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        obj = pyapi.long_from_longlong(args[2]) if integer else pyapi.float_from_double(args[2])
        return _store(builder, pyapi, args[0], args[1], obj)

    value_type = types.int64 if integer else types.float64
    return types.boolean(types.int64, types.int64, value_type), codegen


def _set_row(typingctx, d, key, rows, k):  # pragma: no cover - compiled
    """``d[key] = rows[k]`` (``PySequence_GetItem``: a row view of an array); ``False`` on a
    failure."""
    from llvmlite import ir
    from numba import types
    from numba.core import cgutils

    def codegen(context, builder, signature, args):
        pyapi = context.get_python_api(builder)
        get = cgutils.get_or_insert_function(
            builder.module,
            ir.FunctionType(pyapi.pyobj, [pyapi.pyobj, pyapi.py_ssize_t]),
            "PySequence_GetItem",
        )
        row = builder.call(get, [builder.inttoptr(args[2], pyapi.pyobj), args[3]])
        return _store(builder, pyapi, args[0], args[1], row)

    return types.boolean(types.int64, types.int64, types.int64, types.int64), codegen


def _store(builder, pyapi, d, key, obj):  # pragma: no cover - compiled
    """Code of ``d[key] = obj`` that consumes the new reference ``obj`` (NULL: the call that
    made it failed); whether ``obj`` was stored."""
    from numba.core import cgutils

    stored = cgutils.alloca_once_value(builder, cgutils.false_bit)
    with builder.if_else(cgutils.is_null(builder, obj)) as (failed, made):
        with failed:
            pyapi.err_clear()
        with made:
            status = pyapi.dict_setitem(
                builder.inttoptr(d, pyapi.pyobj), builder.inttoptr(key, pyapi.pyobj), obj
            )
            pyapi.decref(obj)
            ok = builder.icmp_signed("==", status, status.type(0))
            with builder.if_then(builder.not_(ok)):
                pyapi.err_clear()
            builder.store(ok, stored)
    return builder.load(stored)


# Layout of the int64 ``addresses`` argument of :func:`step_infos`.
DICT, TERMINAL, SEGMENT, TASK_REWARD, SEGMENT_REWARD = range(5)
# Results of :func:`step_infos`.
DONE, NOT_HANDLED, INFOS_UNFINISHED = range(3)


def _step_infos(
    addresses,
    infos,
    fmt,
    obs,
    restart,
    final_obs,
    before,
    start,
    clock,
    weights,
    t_bounds,
    settings,
    task_rewards,
    terminated,
    potential,
    reward,
    reward32,
    index,
    new_potential,
    lifted,
    lifted_final,
    lifted_final_address,
    env_rewards,
):  # pragma: no cover - compiled
    """:func:`_step` of a linear task for an SB3 vector step, reading and writing its infos.

    ``infos`` is the address of the list of the sub-envs' info dicts. The final observations of
    the ``restart`` rows are copied from their ``"terminal_observation"`` (format ``fmt``, the
    character code of ``obs``'s dtype) into ``final_obs``; after the step each is replaced by its
    row of ``lifted_final`` (the array at ``lifted_final_address``), and every info gets
    ``"segment"`` (``index[1]``), ``"task_reward"`` (``env_rewards``) and ``"segment_reward"``
    (``reward``). ``addresses`` holds those of ``dict`` and of the four keys.

    Returns ``NOT_HANDLED`` before anything changed when an info is not exactly a ``dict`` or a
    final observation is missing or not a 1-D C-contiguous array of ``obs``'s dtype and width;
    ``INFOS_UNFINISHED`` after the step when a store failed (the stores are idempotent: Python
    can make them all again); ``DONE`` otherwise.
    """
    n = len(restart)
    dict_type = addresses[DICT]
    m = 0  # final observations copied
    for i in range(n):
        info = _list_item(infos, i)
        if info == 0 or _type_of(info) != dict_type:
            return NOT_HANDLED
        if restart[i]:
            _hold(info)
            final = _dict_get(info, addresses[TERMINAL])
            copied = final != 0 and _copy_buffer(final, final_obs[m], fmt)
            _release(info)
            if not copied:
                return NOT_HANDLED
            m += 1
    # Slices, also when m is 0: then no row restarts and _step reads neither.
    _step(
        obs,
        obs,
        final_obs[:m],
        final_obs[:m],
        restart,
        before,
        start,
        clock,
        weights,
        t_bounds,
        settings,
        task_rewards,
        terminated,
        potential,
        reward,
        reward32,
        index,
        new_potential,
        lifted,
        lifted_final[:m],
    )
    j = 0
    for i in range(n):
        info = _list_item(infos, i)
        if info == 0 or _type_of(info) != dict_type:
            return INFOS_UNFINISHED
        # Held: a store can free the value it replaces, and run what that frees.
        _hold(info)
        stored = True
        if restart[i]:
            stored = _set_row(info, addresses[TERMINAL], lifted_final_address, j)
            j += 1
        stored = (
            stored
            and _set_number(info, addresses[SEGMENT], index[1, i])
            and _set_number(info, addresses[TASK_REWARD], env_rewards[i])
            and _set_number(info, addresses[SEGMENT_REWARD], reward[i])
        )
        _release(info)
        if not stored:
            return INFOS_UNFINISHED
    return DONE


def __getattr__(name: str):
    """``step`` and ``step_infos``: :func:`_step` and :func:`_step_infos` compiled, or ``None``
    without numba; built on first use.

    Importing numba takes about half a second, which processes that build no tracker (the
    workers of a ``SubprocVecEnv`` of ``SwirlWrapper`` s, the CLI) do not pay.
    """
    if name not in ("step", "step_infos"):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        import numba
        from numba.extending import intrinsic
    except ImportError:  # optional: the tracker falls back to numpy
        step = step_infos = None
    else:
        # The helpers are compiled into the kernels where they call them by their global names
        # (_step_infos calls the compiled _step).
        for helper in ("_evaluate", "_potential", "_lift_row"):
            globals()[helper] = numba.njit(cache=True, inline="always")(globals()[helper])
        step = globals()["_step"] = numba.njit(cache=True)(_step)
        for helper in (
            "_list_item",
            "_type_of",
            "_hold",
            "_release",
            "_dict_get",
            "_copy_buffer",
            "_set_number",
            "_set_row",
        ):
            globals()[helper] = intrinsic(globals()[helper])
        step_infos = numba.njit(cache=True)(_step_infos)
    globals().update(step=step, step_infos=step_infos)
    return globals()[name]
