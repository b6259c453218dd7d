"""Structural processing: index reduction, causalisation, consistent initialisation.

DAE -> ODE in three steps (../shared/DESIGN.md, sections 2-3):

1. ``casadi.dae_reduce_index`` differentiates the constraints that make the DAE high-index
   (capacitor loops, rigidly coupled masses) and ``dae_map_semi_expl`` gives the semi-explicit
   form x' = f(x, z), 0 = g(x, z) with the dropped constraints as invariants I(x, z) = 0.
2. The algebraic system g is put in block-triangular form (Dulmage-Mendelsohn via
   ``Sparsity.btf``); each block is solved in order: linear blocks explicitly, nonlinear
   blocks (algebraic loops) by Newton's method (``rootfinder``, ``fast_newton``: the plugin
   whose C code generation works). The result is an explicit ODE x' = f(x, z(x)).
3. The initial state solves the invariants and initial equations, completed by start values of
   states chosen greedily (fixed states first) so that the system is square and nonsingular.
"""
from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import warnings
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.linalg

from .dae import CSE_MIN, Dae, steps_read
from ..errors import ModelicaError, UnsupportedConstruct
from . import branches, dummy, homotopy, steady
from .hidden import revealed

log = logging.getLogger(__name__)

#: Largest linear block solved symbolically (an SX model evaluates and differentiates ~10x faster
#: than one holding a run-time solver); larger ones go through a sparse QR at run time.
SYMBOLIC_SOLVE_MAX = 40
#: a linear block of more unknowns is torn before it is solved symbolically (:func:`_linear_solution`)
TEAR_LINEAR_MIN = 8
#: a function with more run-time linear solves than this is left as it is by :func:`fused`
FUSE_STAGES_MAX = 8
#: Largest linear block (above SYMBOLIC_SOLVE_MAX) solved at run time by dense QR, which gives
#: NaN where it is singular (a rotation matrix started at 0), where at least DENSE_FILL of its
#: entries are not structurally zero; a sparser one by sparse QR (which is told not to refuse a
#: pivot, so gives NaN there too): a robot's 375 accelerations and cut forces, 1 % filled, 18x
#: faster (0.28 ms a right-hand side, not 5.1 ms)
DENSE_SOLVE_MAX = 400
DENSE_FILL = 0.1
#: ... through LAPACK, which CasADi writes no C for: an FMU's model is built again with sparse QR
#: (:func:`for_code`), whose generated C gives NaN at a singular point as LAPACK's does
_dense_qr = "lapackqr"
#: a block whose coefficients change with the model's mode is solved symbolically only this
#: small (by minors; see causalise)
MODED_SYMBOLIC_MAX = 3
#: Newton's method on a loop; its derivative (the implicit function's) by sparse QR told not to
#: refuse a pivot, as elsewhere: CasADi's default (CSparse's LU) fails the whole evaluation where
#: the loop's Jacobian is singular (HeatingSystem's initial system, differentiated in its
#: fallback's damped steps, had no value at all)
NEWTON_OPTS = {"abstol": 1e-12, "max_iter": 50, "linear_solver": "qr", "linear_solver_options": {"eps": -1.0}}
#: an algebraic loop's residual accepted from Newton's method without the fallback
LOOP_TOL = 1e-9
#: a preferred variable's pin whose row (the states' columns scaled to 1) is below this moves no state
WISH_FLOOR = 1e-12
#: an initial system's residual above this after every fallback: no consistent start (NaN)
INIT_TOL = 1e-6
#: a loop's row is met to LOOP_TOL or to a thousand rounding errors of its terms' sum, the
#: larger (see _met)
ROUNDING = 1e3 * np.finfo(float).eps / LOOP_TOL
DAMPED_ITERATIONS = 30       # Newton steps with a line search (the fallback)
LINE_SEARCH_STEPS = 12       # step lengths tried: 1, 1/2, ..., 1/2^11
BRACKET_STEPS = 20           # a scalar loop's fallback: sign changes sought out to 1e-3 x 4^19
BISECTIONS = 80              # ... and the interval then halved (1e9 down to 1e-15)
#: a hybrid model's function holding loops stays SX up to this many instructions (a loop's
#: solve unrolled, with its fallbacks, is 5 000-50 000: MX then evaluates only what it needs)
COMPACT_SX_MAX = 20000
#: ... and is not even expanded where :func:`expanded_size` estimates more than this (the
#: estimate is within a factor of 6 or so: HeatingRectifier 1.2e5 for 2e4; a fluid model's loops,
#: 6e8, took 130 s a function to expand)
EXPAND_TRY_MAX = 50 * COMPACT_SX_MAX
#: hold a loop of one unknown with branches on the branch its last solution was on (see
#: causalise): an op-amp relaxation oscillator then swings with its textbook period, where
#: solved anew at each call it stays at a threshold. True: every such loop; None: only a loop
#: with several solutions (:func:`_several_solutions`: positive feedback). Not every loop: the
#: comparisons' events and crossing functions hold a loop solve each, and cost 5-70x on diode
#: and amplifier circuits that need none (HeatingRectifier 0.4 -> 27 s of simulation)
HOLD_BRANCHES: bool | None = None
#: ... a loop with more comparisons than this is not looked at (2^n branches to compare)
HOLD_COMPARISONS_MAX = 6
#: a loop of several unknowns with at most this many comparisons that Newton's method and its
#: fallback do not solve is solved on each combination of its branches (:func:`_branchwise`)
BRANCHES_MAX = 2
#: a pivot that reads more modes than this is not tried in each of them (2^n), nor divided by
MODES_TRIED_MAX = 6


@dataclass
class Ode:
    """Explicit ODE of a compiled model; every function takes (x, u, p, t) unless said."""

    x_names: list[str]
    u_names: list[str]
    p_names: list[str]
    y_names: list[str]
    p_values: np.ndarray
    u_start: np.ndarray
    ode: ca.Function        # -> x'
    out: ca.Function        # -> y
    alg_res: ca.Function    # -> max |g(x, z(x))| (0 unless there are algebraic loops)
    drift: ca.Function      # -> max |I(x, z(x))|: invariants dropped by index reduction
    init: ca.Function       # (u, p, t) -> x0
    probe: ca.Function      # -> every named variable, in order ``probe_names``
    checks: ca.Function     # -> (y, alg_res, drift) with one solve of the algebraic loops
    probe_names: list[str]
    index: int
    nonlinear_blocks: int
    time_events: tuple = ()      # the solvers restart at these instants
    zero: ca.Function | None = None   # -> zero-crossing functions: a sign change is a state event
    start: ca.Function | None = None       # p -> the states' start values s
    init_start: ca.Function | None = None  # (u, p, t, s) -> x0 from start values s (FMU starts)
    # -- hybrid models: the last ``discrete`` entries of x are discrete variables (and when-
    # condition memories), with a zero derivative; they change only at events
    discrete: int = 0
    update: ca.Function | None = None      # (x, u, p, t, pre, flags) -> x: one event-iteration step
    init_discrete: ca.Function | None = None   # (u, p, t, d) -> continuous x0 given the discrete d
    asserts: ca.Function | None = None     # -> 1 where an assert is violated (see events["asserts"])
    events: dict | None = None             # {"clocks": [[start, period]], "flags": [...], "asserts": [[level, msg]]}
    # -- models with algebraic loops: derivatives through the loops' Newton form
    loops: ca.Function | None = None       # -> the loops' solutions zl
    given: ca.Function | None = None       # (x, u, p, t, zl) -> (x', probe): the model at zl (SX)
    # -- where the loops' Newton methods start: ``guess0`` set, every function's p ends with a
    # guess per algebraic unknown (a run passes the last solution: an amplifier with positive
    # feedback stays on its branch); the functions above, with ``warm`` set, start them from
    # the start values (an FMU, a sensitivity along a run)
    solved: ca.Function | None = None      # -> the algebraic unknowns: the next guesses
    guess0: np.ndarray | None = None       # the start values, the guesses before a run's first solve
    warm: "Ode | None" = None              # this model with the guesses an argument
    #: the largest residual of the initial equations at the initial state found (the model's
    #: parameter values; inf where no initial state is found)
    init_unmet: float = 0.0


def reduce_index(dae: Dae, select: bool = True):
    """Index reduction (step 1); returns the semi-explicit DAE and the map back to ``dae``
    (``select``: states selected by dummy derivatives where the constraints are nonlinear)."""
    up = ca.vertcat(dae.u, dae.p)
    if dae.x.numel() == 0:     # purely algebraic: nothing to reduce (and CasADi crashes on it)
        xs = ca.SX(0, 1)
        semi = dict(x=xs, z=dae.z, p=up, t=dae.t, ode=ca.SX(0, 1), alg=dae.residual)
        state_to_orig = ca.Function("state_to_orig", [xs, dae.z], [ca.SX(0, 1), dae.z],
                                    ["xf", "zf"], ["x_impl", "z"])
        return semi, state_to_orig, ca.SX(0, 1), 0
    w = ca.vertcat(dae.dx, dae.z)
    if ca.sprank(ca.jacobian_sparsity(dae.residual, w)) == dae.residual.numel():
        # index 1 (the equations determine x' and z): the semi-explicit form is x' = dx with
        # (dx, z) algebraic, what dae_map_semi_expl gives, without dae_reduce_index's search
        # (cubic in the model's size: 87 s for 800 R-C sections)
        semi = dict(x=dae.x, z=w, p=up, t=dae.t, ode=dae.dx, alg=dae.residual)
        state_to_orig = ca.Function("state_to_orig", [dae.x, w], [dae.dx, dae.x, dae.z],
                                    ["xf", "zf"], ["dx_impl", "x_impl", "z"])
        return semi, state_to_orig, ca.SX(0, 1), 1
    impl = dict(x_impl=dae.x, dx_impl=dae.dx, z=dae.z, alg=dae.residual, t=dae.t, p=up)
    try:
        red, stats = ca.dae_reduce_index(impl, {})
        semi, state_to_orig, _phi = ca.dae_map_semi_expl(impl, red)
    except RuntimeError:
        # CasADi's slips where a variable is differentiated twice (a joint's angle in a
        # multibody chain), or its reduction is one its own map calls singular (a filter's
        # output differentiated three times): the same algorithm, assembled by variable
        from .pantelides import reduce_index as pantelides

        red, stats = pantelides(impl)
        try:
            semi, state_to_orig, _phi = ca.dae_map_semi_expl(impl, red)
        except RuntimeError as exc:
            raise ModelicaError(f"index reduction failed (structurally singular model?): "
                                f"{str(exc).strip().splitlines()[-1]}") from None
    if ca.depends_on(red["I"], dae.u):
        used = [n for i, n in enumerate(dae.u_names) if ca.depends_on(red["I"], dae.u[i])]
        raise UnsupportedConstruct(
            f"the model needs the time derivative of input(s) {', '.join(used)} (an input drives "
            "a constraint that index reduction differentiates, e.g. a voltage source directly "
            "across a capacitor); add a series element or give the input as a state")
    if select and _nonlinear(red["I"], ca.vertcat(up, dae.t)):
        # the states would drift off nonlinear constraints: states selected by dummy derivatives
        selected = dummy.select(impl, [*dae.x_names, *dae.z_names], _state_select(dae),
                                _start_values(ca.vertcat(dae.x, dae.z), dae),
                                np.concatenate([np.asarray(dae.u_start, float).ravel(), dae.p_values]),
                                ca.vertcat(*[dae.p[i] for i, n in enumerate(dae.p_names) if n.startswith("$")]))
        if selected is not None:
            return (*selected, ca.SX(0, 1), int(stats["index"]))
        log.debug("no dummy derivatives: states integrated with their constraints dropped")
    return semi, state_to_orig, red["I"], int(stats["index"])


def _state_select(dae: Dae) -> dict:
    """Each unknown's ``stateSelect``, the highest of its own and its aliases' (a rolling
    wheel's ``x``, declared ``always``, is an alias of its frame's ``r_0[1]``, ``avoid``)."""
    name_of = {v.element_hash(): n for v, n in zip(ca.vertsplit(ca.vertcat(dae.x, dae.z)),
                                                   [*dae.x_names, *dae.z_names])}
    out = {}
    for name, sel in dae.state_select.items():
        e = dae.exprs.get(name)
        syms = ca.symvar(e) if e is not None else []
        target = name_of.get(syms[0].element_hash(), name) if len(syms) == 1 else name
        if target not in out or dummy.RANK.get(sel, 0) > dummy.RANK.get(out[target], 0):
            out[target] = sel
    return out


def _fixed_kept(dae: Dae, xs: ca.SX) -> Dae:
    """``dae`` with the fixed start of each state that state selection made algebraic an
    initial equation (x = start)."""
    kept = {s.element_hash() for s in ca.vertsplit(xs)}
    gone = [i for i, s in enumerate(ca.vertsplit(dae.x)) if dae.x_fixed[i] and s.element_hash() not in kept]
    if not gone:
        return dae
    rows = ca.vertcat(*[dae.x[i] - dae.x_start[i] for i in gone])
    return dataclasses.replace(dae, init_residual=ca.vertcat(dae.init_residual, rows))


def _nonlinear(invariants: ca.SX, known: ca.SX) -> bool:
    """Do the invariants index reduction dropped read their unknowns (not the ``known``
    inputs, parameters and time) nonlinearly?"""
    given = {s.element_hash() for s in ca.vertsplit(known)}
    v = [s for s in ca.symvar(invariants) if s.element_hash() not in given]
    return bool(v) and ca.depends_on(ca.jacobian(invariants, ca.vertcat(*v)), ca.vertcat(*v))


def _preferred_states(dae: Dae, semi: dict, state_to_orig: ca.Function) -> Dae:
    """``dae`` with the variables declared ``stateSelect = prefer`` (or ``always``) made states,
    as Modelica tools select them, where its semi-explicit form ``semi`` solves them in a
    nonlinear loop that decides events or solves more than one of them (a medium's state):
    a fluid volume's mass and energy are what its balances differentiate, but its pressure
    and enthalpy are preferred, and from mass and energy they are a Newton solve through the
    medium's functions at every evaluation. Where that loop decides events, IF97 water's
    phase (an Integer) followed the iterate and the event iteration never settled; where it
    does not, a pump's 0.05 l of water kept its mass as a state, and its pressure from that
    mass through the bulk modulus made the run stiff (PumpingSystem: 411 000 steps in 5 s,
    against 234). As states they are integrated; index reduction differentiates the
    equations that give mass and energy from them, and those equations hold as invariants.
    ``dae`` itself where no preferred variable is in such a loop."""
    # (a preferred variable may be an alias of the algebraic unknown that stands for it)
    z_at = {v.element_hash(): i for i, v in enumerate(ca.vertsplit(dae.z))}
    exprs = [dae.exprs.get(n) for n in dae.preferred]
    preferred = sorted({z_at[e.element_hash()] for e in exprs
                        if e is not None and e.is_symbolic() and e.element_hash() in z_at})
    zs, g = semi["z"], semi["alg"]
    if not preferred or not zs.numel():
        return dae
    z_orig = ca.vertsplit(state_to_orig(xf=semi["x"], zf=zs)["z"])
    col = {s.element_hash(): c for c, s in enumerate(ca.vertsplit(zs))}
    in_semi = {col[z_orig[i].element_hash()]: i for i in preferred
               if z_orig[i].is_symbolic() and z_orig[i].element_hash() in col}
    sp = ca.jacobian_sparsity(g, zs)
    if not in_semi or ca.sprank(sp) < zs.numel():
        return dae
    gs, ws = ca.vertsplit(g), ca.vertsplit(zs)
    # what the event iteration reads: the relations, the discrete variables' updates
    switching = ca.vertcat(dae.relations, *[e for n, e in dae.exprs.items() if n.startswith("$update[")])
    looped = set()
    for rows, cols in _blocks(sp, zs.numel()):
        mine = [in_semi[c] for c in cols if c in in_semi]
        if mine:
            gk, wk = ca.vertcat(*[gs[r] for r in rows]), ca.vertcat(*[ws[c] for c in cols])
            # (one preferred variable alone in a loop that decides no event is left to it: a
            # coil's flux, solved through the saturating law a discovery puts into its core,
            # made a state beside the current, and that law's fit failed)
            if ca.depends_on(ca.jacobian(gk, wk), wk) and (len(mine) > 1 or ca.depends_on(switching, wk)):
                looped.update(mine)
    if not looped:
        return dae
    chosen = sorted(looped)
    rest = [i for i in range(dae.z.numel()) if i not in looped]
    pick = lambda v, idx: ca.vertcat(*[v[i] for i in idx]) if idx else ca.SX(0, 1)      # noqa: E731
    dv = ca.vertcat(*[ca.SX.sym(f"der({dae.z_names[i]})") for i in chosen])
    log.debug("preferred variables made states: %s", [dae.z_names[i] for i in chosen])
    return dataclasses.replace(
        dae, x=ca.vertcat(dae.x, pick(dae.z, chosen)), dx=ca.vertcat(dae.dx, dv), z=pick(dae.z, rest),
        x_names=[*dae.x_names, *[dae.z_names[i] for i in chosen]], z_names=[dae.z_names[i] for i in rest],
        x_start=ca.vertcat(dae.x_start, pick(dae.z_start, chosen)), z_start=pick(dae.z_start, rest),
        x_fixed=np.concatenate([np.asarray(dae.x_fixed, bool), np.zeros(len(chosen), bool)]))


@contextlib.contextmanager
def for_code():
    """ODEs built within solve every linear block by a solver CasADi generates C for."""
    global _dense_qr
    _dense_qr = "qr"
    try:
        yield
    finally:
        _dense_qr = "lapackqr"


def _blocks(sp: ca.Sparsity, nz: int):
    """BTF blocks of the algebraic Jacobian's sparsity ``sp`` in solving order: [(rows, cols)]."""
    if ca.sprank(sp) < nz:
        raise ModelicaError(
            f"the algebraic equations are structurally singular ({ca.sprank(sp)} of {nz} "
            "variables determined): an equation is missing or a variable is over-constrained")
    _, rowperm, colperm, rowblock, colblock, _, _ = sp.btf()
    blocks = [(list(rowperm[rowblock[k]:rowblock[k + 1]]), list(colperm[colblock[k]:colblock[k + 1]]))
              for k in range(len(rowblock) - 1)]
    rows, cols = sp.get_triplet()

    def upper(bl):  # does some block depend on a later one?
        row_block = {r: k for k, (rs, _) in enumerate(bl) for r in rs}
        col_block = {c: k for k, (_, cs) in enumerate(bl) for c in cs}
        return any(col_block[c] > row_block[r] for r, c in zip(rows, cols))

    if upper(blocks):
        blocks = blocks[::-1]
        assert not upper(blocks), "BTF order"
    return blocks


def _has_calls(g: ca.SX, z: ca.SX, args: list[ca.SX]) -> bool:
    """Whether ``g`` holds call nodes (the functions a model's FMU keeps as calls)."""
    return _calls_in(ca.Function("g", [z, *args], [g]))


def _calls_in(f: ca.Function) -> bool:
    """Whether SX function ``f`` holds call nodes."""
    return any(f.instruction_id(k) == ca.OP_CALL for k in range(f.n_instructions()))


def _unread_set(gs: list, rows, z_at: dict, read: set, z_guess: np.ndarray) -> None:
    """The unknowns that rows ``rows`` of ``gs`` name but do not depend on, set to their guesses:
    a call node names all of its function's inputs, and so does its derivative, though an
    output depends on some only (a pump's block named an unknown of a later block through a
    medium's function; its solution was then not a function of what the block reads). Their
    value changes nothing; a block's function must not take them."""
    skip = read | {-1}          # (-1: a symbol that is no unknown)
    for r in rows:
        named = [s for s in ca.symvar(gs[r]) if z_at.get(s.element_hash(), -1) not in skip]
        if named:
            gs[r] = ca.substitute([gs[r]], named, [ca.SX(float(z_guess[z_at[s.element_hash()]])) for s in named])[0]


def causalise(g: ca.SX, z: ca.SX, args: list[ca.SX], z_guess: np.ndarray, modes: ca.SX | None = None,
              guess: ca.SX | None = None, nominal: list[np.ndarray] | None = None, homotopic=None,
              short: bool = True):
    """Solve 0 = g(z, args) for z block by block; returns (Function args -> z, #nonlinear blocks,
    the Newton form or None). ``guess`` (a symbol like z): the loops' Newton methods start
    there, an argument after ``args`` (a run passes the last solution), instead of ``z_guess``;
    the Function then also gives, per loop with branches (a comparison in its residual: an
    amplifier's limits), 1 where Newton's method converged from the guess and -1 where it did
    not (its branch has ended: a relaxation oscillator's amplifier flips, see Ode.warm).

    Linear blocks A z_k + b = 0 are solved symbolically (small) or by sparse QR (large);
    nonlinear blocks by Newton's method started from ``z_guess``, on their tearing variables
    (:func:`_tear`).

    The Newton form serves derivatives: (Function args -> the loops' solutions zl, SX Function
    (args, zl) -> z) where each loop's unknowns are z_l - J^-1 g at the given zl. At the solution
    (g = 0) that is z itself and its first derivatives in args are the implicit function's
    (-J^-1 dg/dargs) and zero in zl: a Jacobian along a run is then one Newton solve per point
    and SX algebra, instead of the solver's own derivatives through the MX graph (30x slower).
    None when there is no loop, or a block is too large to solve symbolically.

    ``nominal``: values of ``args`` (start values, parameters) where a loop's branches are
    compared (see :data:`HOLD_BRANCHES`). ``homotopic``: (g with homotopy's lambda, lambda):
    a loop that reads lambda starts where lambda leads it (its entries of ``z_guess`` set).
    ``short``: the blocks' large if-branches evaluated only when taken (:mod:`.branches`),
    for functions called at every step; an initial system's, solved a few times, is not worth
    the rewriting (a heat exchanger's took 120 of its 400 CPU-s so).
    """
    short_circuited = branches.short_circuited if short else (lambda f: f)
    sp = ca.jacobian_sparsity(g, z)     # structural: an unknown read in a condition counts
    blocks = _blocks(sp, z.numel())
    reads: dict[int, set] = {}          # row -> the unknowns it reads
    for r, c in zip(*sp.get_triplet()):
        reads.setdefault(r, set()).add(c)
    gs, zs = ca.vertsplit(g), ca.vertsplit(z)
    args = [*args, guess] if guess is not None else args
    mx_args = [ca.MX.sym(f"a{i}", a.sparsity()) for i, a in enumerate(args)]
    solved: dict[int, ca.MX] = {}
    free: dict[int, ca.MX] = {}         # z with each loop's branch sought anew (see ``guess``)
    newton: dict[int, ca.SX] | None = {}      # the Newton form's z, in args and the loops' zl
    zl_syms, zl_sols = [], []
    held, now, crossings, ops = [], [], [], []     # per loop with branches: its comparisons
    n_nonlinear = 0
    running = ca.vertcat(args[0], args[2])     # states and time (blocks that read a mode are not symbolic)
    stepped = steps_read(g, z)        # per row, the unknowns it reads through a step
    mode_names = {str(m) for m in ca.vertsplit(modes)} if modes is not None else set()
    mode_at = [n for n, a in enumerate(ca.vertsplit(ca.vertcat(*args))) if str(a) in mode_names]
    z_at = {s.element_hash(): c for c, s in enumerate(zs)} if _has_calls(g, z, args) else None
    for k, (rows, cols) in enumerate(blocks):
        prev = sorted(set().union(*[reads.get(r, set()) for r in rows]) - set(cols))
        if z_at is not None:
            _unread_set(gs, rows, z_at, set(cols) | set(prev), z_guess)
        gk, zk = ca.vertcat(*[gs[r] for r in rows]), ca.vertcat(*[zs[c] for c in cols])
        zprev = ca.vertcat(*[zs[c] for c in prev]) if prev else ca.SX(0, 1)
        prev_mx = ca.vertcat(*[solved[c] for c in prev]) if prev else ca.MX(0, 1)
        prev_free = ca.vertcat(*[free[c] for c in prev]) if prev else ca.MX(0, 1)
        prev_sx = ca.vertcat(*[newton[c] for c in prev]) if prev and newton is not None else ca.SX(0, 1)
        A = ca.jacobian(gk, zk)
        # a block whose coefficients change with the model's mode (a clutch's locked: sa's
        # coefficient is 0 or 1) is solved at run time: eliminated symbolically, its pivots
        # would be chosen for one mode and divide by zero in another. Up to 3 unknowns
        # CasADi solves by minors, which divide by the determinant alone: such a block (a
        # diode pair's, its relations held), or one torn down to that many by pivots that
        # are the same in every mode (a diode bridge's), is solved symbolically in every mode
        moded = modes is not None and modes.numel() > 0 and ca.depends_on(A, modes)
        own = sum(1 << c for c in cols)
        linear = not ca.depends_on(A, zk) and not any(stepped[r] & own for r in rows)
        torn, residual, whole = ([], None, None) if linear else _tear([gs[r] for r in rows], [zs[c] for c in cols])
        if len(torn) > 1 and guess is not None and nominal is not None and HOLD_BRANCHES is not False:
            torn, residual, whole = _torn_to_one(gk, zk, zprev, rows, cols, gs, zs, ca.vertcat(z, running), modes,
                                                 args, nominal, (torn, residual, whole))
        sol_free = None
        if linear:
            b = ca.substitute(gk, zk, ca.SX.zeros(zk.sparsity()))
            changing = ca.depends_on(A, ca.vertcat(zprev, running))      # coefficients that change in a run
            sol_sx = _linear_solution(gk, zk, A, b, z_guess[cols] if changing else None,
                                      MODED_SYMBOLIC_MAX if moded else SYMBOLIC_SOLVE_MAX)
            if sol_sx is not None:
                f = short_circuited(ca.Function(f"blk{k}", [zprev, *args], [sol_sx]))
                block = (lambda pv, f=f: f(pv, *mx_args))
                sol_newton = f(prev_sx, *args) if newton is not None else None
            else:
                fa = ca.Function(f"blk{k}", [zprev, *args], [A, b])
                # (a switch's block of a few unknowns, solved here for its modes: sparse, 20 % faster;
                # dense QR there changed a lossy gear's rounding enough that its modes chattered)
                dense = SYMBOLIC_SOLVE_MAX < len(cols) <= DENSE_SOLVE_MAX and A.nnz() >= DENSE_FILL * len(cols) ** 2
                how = _dense_qr if dense else "qr"
                # (fa's inputs at the start values: the guesses last, where it takes them)
                at = None if nominal is None else _nominal_par(nominal, z_guess, prev)[:sum(a.numel() for a in [zprev, *args])]
                g0 = z_guess[cols] if at is None or _singular_in_a_mode(fa, at, mode_at, len(prev)) else None
                block = (lambda pv, fa=fa, how=how, g0=g0: _run_time_solve(*fa(pv, *mx_args), how, g0))
                newton = None
        elif not torn:      # explicit in order (a step read an unknown known by then): no loop
            f = short_circuited(ca.Function(f"blk{k}", [zprev, *args], [whole]))
            block = (lambda pv, f=f: f(pv, *mx_args))
            sol_newton = f(prev_sx, *args) if newton is not None else None
        else:
            if homotopic is not None and nominal is not None:
                _homotopy_start(homotopic, rows, zk, zprev, args, mx_args, prev_free, nominal, z_guess, cols)
            tears = ca.vertcat(*[zs[cols[i]] for i in torn])
            n_nonlinear += 1
            par = ca.vertcat(zprev, *args)
            resid = ca.Function(f"loop{k}", [tears, par], [residual])
            at = [cols[i] for i in torn]
            first = z_guess[at] if guess is None else mx_args[-1][at]      # Newton's first iterate
            spread = short_circuited(ca.Function(f"torn{k}", [tears, zprev, *args], [whole]))

            def block(pv, resid=short_circuited(resid), first=first, spread=spread, name=f"loop{k}", extra=(), at=at):
                t_sol = _loop_solve(name, resid, first, ca.vertcat(pv, *mx_args, *extra),
                                    start=None if guess is None else z_guess[at])
                return spread(t_sol, pv, *mx_args, *extra), t_sol
            cmps = _replay(resid, [tears, par])[1] if guess is not None and len(torn) == 1 and HOLD_BRANCHES is not False else []
            if cmps and HOLD_BRANCHES is None and (nominal is None or not _several_solutions(
                    resid, [tears, par], cmps, z_guess[at], _nominal_par(nominal, z_guess, prev))):
                cmps = []
            if cmps:
                # a law with branches (an amplifier's limits) is held on the branch its last
                # solution was on, its comparisons' values an argument (as a relation is held
                # between events), and an event is where one of them would change: a solution
                # sought anew could jump back to a branch just left (a relaxation oscillator
                # chatters), and the solver meets no jump between events. Only a loop of one
                # unknown: at a branch's end its next one is then bracketed (from two, Newton's
                # methods can miss it next to the end: the non-inverting Schmitt trigger)
                h = ca.SX.sym(f"h{k}", len(cmps))
                out, _, cross, how = _replay(resid, [tears, par], h)
                resid_h = ca.Function(f"loop{k}h", [tears, ca.vertcat(par, h)], out)
                held.append(ca.MX.sym(f"held{k}", len(cmps)))
                sol_free, t_free = block(prev_free)
                now.append(ca.Function(f"cmp{k}", [tears, par], [ca.vertcat(*cmps)])(t_free, ca.vertcat(prev_free, *mx_args)))
                # (the unknowns computed from the tearing variable read the same comparisons,
                # held too: an amplifier's output from its input, where the input is torn)
                sp_in = [tears, zprev, *args]
                spread_h = ca.Function(f"torn{k}h", [*sp_in, h], _replay(
                    ca.Function(f"torn{k}", sp_in, [whole]), sp_in, h, match=cross)[0])
                sol, t_sol = block(prev_mx, resid=resid_h, name=f"loop{k}h", extra=(held[-1],), spread=spread_h)
                crossings.append(ca.Function(f"cross{k}", [tears, par, h], [ca.vertcat(*cross)])(
                    t_sol, ca.vertcat(prev_mx, *mx_args), held[-1]))
                ops += how
            else:
                sol, t_sol = block(prev_mx)
            loop_block, block = block, None
            if tears.numel() <= SYMBOLIC_SOLVE_MAX and newton is not None:
                zl = ca.SX.sym(f"zl{k}", tears.numel())
                J = ca.jacobian(residual, tears)
                # (where J is singular, the least-squares step: a pipe between two closed
                # valves fixes its pressure only to what its head allows, and the Newton step,
                # infinite there, left a NaN in every Jacobian of ControlledTanks' run)
                newton_step = ca.solve(J, residual) if tears.numel() > 1 else residual / J
                step = tears - _or_nearest(newton_step, J, -residual, np.zeros(tears.numel()))
                sol_newton = spread(ca.Function(f"newton{k}", [tears, zprev, *args], [step])(zl, prev_sx, *args),
                                    prev_sx, *args)
                zl_syms.append(zl)
                zl_sols.append(t_sol)
            else:
                newton = None
        if block is not None:
            sol = block(prev_mx)
        if sol_free is None:      # the same as held unless a loop before it has branches
            sol_free = sol if not held else block(prev_free) if block is not None else loop_block(prev_free)[0]
        for i, c in enumerate(cols):
            solved[c], free[c] = sol[i], sol_free[i]
            if newton is not None:
                newton[c] = sol_newton[i]
    nz = z.numel()
    zsol = ca.vertcat(*[solved[c] for c in range(nz)]) if nz else ca.MX(0, 1)
    # the comparisons held: one argument, after the guesses
    H = ca.MX.sym("held", sum(h.numel() for h in held))
    at = np.cumsum([0] + [h.numel() for h in held]).tolist()
    zl_sol, cross = ca.vertcat(*zl_sols), ca.vertcat(*crossings)
    if held:
        zsol, zl_sol, cross = ca.substitute([zsol, zl_sol, cross], held, [H[a:b] for a, b in zip(at, at[1:])])
    form = None
    if newton is not None and n_nonlinear:
        ZL = ca.vertcat(*zl_syms)
        form = (ca.Function("loops", mx_args if guess is None else [*mx_args, H], [zl_sol]),
                ca.Function("z_newton", [*args, ZL], [ca.vertcat(*[newton[c] for c in range(nz)])]))
    if guess is None:
        return fused(ca.Function("zsol", mx_args, [zsol])), n_nonlinear, form
    zfree = ca.vertcat(*[free[c] for c in range(nz)]) if nz else ca.MX(0, 1)
    fun = fused(ca.Function("zsol", [*mx_args, H], [zsol, zfree, ca.vertcat(*now) if now else ca.MX(0, 1), cross]))
    return fun, n_nonlinear, form, ops


def _homotopy_start(homotopic, rows, zk, zprev, args, mx_args, prev_free, nominal, z_guess, cols):
    """The loop's start values (``z_guess[cols]``) where homotopy leads it, its unknowns solved
    before it at the start values (see :mod:`homotopy`)."""
    g_h, lam = homotopic
    rows_h = ca.vertcat(*[g_h[r] for r in rows])
    if not ca.depends_on(rows_h, lam):
        return
    at = [*nominal, z_guess][:len(mx_args)]
    try:
        pv = np.array(ca.Function("prev", mx_args, [prev_free])(*at), float).ravel() if zprev.numel() else np.zeros(0)
    except RuntimeError:
        return
    par = ca.vertcat(zprev, *args[:len(nominal)])
    found = homotopy.guess(rows_h, lam, zk, par, np.concatenate([pv, *[np.ravel(a) for a in nominal]]),
                           np.asarray(z_guess)[cols])
    if found is not None:
        z_guess[cols] = found


def _several_solutions(resid: ca.Function, inputs: list, cmps: list, t0, par0) -> bool:
    """Whether a loop of one unknown t with branches may have several solutions: its residual
    rises in t on one branch and falls on another, at the start values and parameters. An
    amplifier with positive feedback (a Schmitt trigger: 1 - k V0 where linear, 1 where
    saturated) has, and is held on its branch; a diode's or a limiter's in negative feedback
    rises on every branch, and its one solution is sought anew at each call."""
    if len(cmps) > HOLD_COMPARISONS_MAX:
        return False
    signs = set()
    for law in _branch_laws(resid, inputs, len(cmps)):
        try:
            v = float(ca.Function("slope", inputs, [ca.jacobian(law, inputs[0])])(t0, par0))
        except RuntimeError:
            continue
        if math.isfinite(v) and abs(v) > 0:
            signs.add(v > 0)
    return len(signs) > 1


def _branch_laws(resid: ca.Function, inputs: list, n: int) -> list:
    """The loop's residual on ``inputs`` with its ``n`` comparisons fixed, one expression for
    each combination of their values (all false first)."""
    h = ca.SX.sym("h", n)
    out = _replay(resid, inputs, h)[0][0]
    return [ca.substitute(out, h, ca.DM(combo)) for combo in itertools.product((0.0, 1.0), repeat=n)]


def _nominal_par(nominal: list[np.ndarray], z_guess: np.ndarray, prev: list[int]) -> np.ndarray:
    """A loop's parameter vector (the unknowns solved before it, the args, the guesses) at the
    start values."""
    return np.concatenate([np.asarray(z_guess)[prev], *[np.ravel(a) for a in nominal], z_guess])


def _replay(f: ca.Function, inputs: list, held: ca.SX | None = None, match: list | None = None):
    """``f`` (an SX Function) rebuilt on ``inputs``: (its outputs, its comparisons a < b and a <=
    b in order, their crossing functions a - b, their operators), with the comparisons'
    values taken from ``held`` where it is given: the k-th comparison's from held[k], or with
    ``match`` (crossing functions) from the entry of the one it equals (none: not held)."""
    if _calls_in(f):
        return f.call(inputs), [], [], []      # (a branch short-circuited: its comparisons not seen)
    work, outs = {}, [[None] * f.nnz_out(i) for i in range(f.n_out())]
    cmps, cross, ops = [], [], []
    for k in range(f.n_instructions()):
        op, i, o = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[o[0]] = inputs[i[0]].nz[i[1]]
        elif op == ca.OP_OUTPUT:
            outs[o[0]][o[1]] = work[i[0]]
        elif op == ca.OP_CONST:
            work[o[0]] = ca.SX(f.instruction_constant(k))
        elif op in (ca.OP_LT, ca.OP_LE):
            a, b = work[i[0]], work[i[1]]
            cmps.append(ca.SX.binary(op, a, b))
            cross.append(a - b)
            ops.append("less" if op == ca.OP_LT else "less_equal")
            # (a value held < 0: none yet, the comparison itself, as where the loop starts
            # from its start values: an FMU's, the initial system's)
            if match is not None:
                h = next((held[i] for i, c in enumerate(match) if ca.is_equal(c, cross[-1], 64)), None)
            else:
                h = held[len(cmps) - 1] if held is not None else None
            work[o[0]] = cmps[-1] if h is None else ca.if_else(h < 0, cmps[-1], h)
        elif len(i) == 1:
            work[o[0]] = ca.SX.unary(op, work[i[0]])
        else:
            work[o[0]] = ca.SX.binary(op, work[i[0]], work[i[1]])
    outs = [ca.SX(f.sparsity_out(n), ca.vertcat(*nz) if nz else ca.SX(0, 1)) for n, nz in enumerate(outs)]
    return outs, cmps, cross, ops


def _torn_to_one(gk, zk, zprev, rows, cols, gs, zs, moving, modes, args, nominal, torn):
    """A loop with branches (an amplifier's limits) torn to one unknown, where dividing by
    coefficients of parameters alone (a resistance), nonzero at their values, makes it so:
    only such a loop is held on its branch (see :func:`causalise`); else ``torn`` as it is.
    A coefficient that reads the model's modes (``modes``: held relations, set at events) must
    be nonzero in each of them: a check valve's s > 0 made s's coefficient 1 shut and 0 open,
    and the loop, torn at its start (shut), divided by 0 once the valve opened."""
    par = ca.vertcat(zprev, *args)
    if not _replay(ca.Function("rows", [zk, par], [gk]), [zk, par])[1]:
        return torn
    values = [np.ravel(a) for a in nominal]
    mode_list = ca.vertsplit(modes) if modes is not None else []

    def steady(coef):
        if ca.depends_on(coef, moving):
            return False
        read = [m for m in mode_list if ca.depends_on(coef, m)]
        if len(read) > MODES_TRIED_MAX:
            return False
        for combo in itertools.product((0.0, 1.0), repeat=len(read)):
            at = ca.substitute(coef, ca.vertcat(*read), ca.DM(combo)) if read else coef
            try:
                v = float(ca.Function("coef", args[:len(nominal)], [at])(*values))
            except RuntimeError:
                return False
            if not (math.isfinite(v) and abs(v) > 0):
                return False
        return True
    loose = _tear([gs[r] for r in rows], [zs[c] for c in cols], steady)
    return loose if len(loose[0]) == 1 else torn


def _tear(rows: list, unknowns: list, steady=None):
    """An algebraic loop torn: (the positions of its tearing variables t among ``unknowns``,
    residual r(t), the loop's unknowns as expressions of t). An unknown that an equation gives explicitly once the ones before are
    known (it appears there linearly, with a constant coefficient: a parameter's could be set
    to 0, w1 in w1*i = v^3, and the loop would then pass for solvable) is computed, not
    iterated; where none is, the unknown read by most open equations becomes a tearing
    variable (the usual greedy heuristic). Newton's method then runs on t alone and never
    starts where an explicit unknown's start value is meaningless: a spring's length of 0
    dividing a force (three MultiBody springs meeting at a massless point). ``steady(coef)``:
    whether a coefficient that is not constant may still be divided by."""
    n = len(unknowns)
    g, z = ca.vertcat(*rows), ca.vertcat(*unknowns)
    reads: list[set] = [set() for _ in rows]
    for r, j in zip(*ca.jacobian_sparsity(g, z).get_triplet()):
        reads[r].add(j)

    pivots: dict[tuple[int, int], bool] = {}
    stepped = steps_read(g, z)                  # per row, the unknowns it reads through a step

    def pivot(r, j):                            # (asked again each pass: kept)
        if (r, j) not in pivots:
            coef = ca.jacobian(rows[r], unknowns[j])
            pivots[r, j] = (coef.is_constant() and float(coef) != 0 or steady is not None and steady(coef)) and \
                not stepped[r] >> j & 1
        return pivots[r, j]

    order, tears, residual, decided = [], [], [], set()
    open_rows = list(range(len(rows)))
    while open_rows:
        for r in open_rows:
            left = reads[r] - decided
            if not left or (len(left) == 1 and pivot(r, next(iter(left)))):
                (residual if not left else order).append((r, *left))
                decided |= left
                open_rows.remove(r)
                break
        else:                                   # nothing explicit: tear the most read unknown
            counts: dict[int, int] = {}
            for r in open_rows:
                for j in reads[r] - decided:
                    counts[j] = counts.get(j, 0) + 1
            j = max(sorted(counts), key=counts.get)
            tears.append(j)
            decided.add(j)
    if len(tears) >= n or len(residual) != len(tears):
        return list(range(n)), g, z
    syms, vals = [], []                         # the explicit unknowns, as expressions of t
    value = {j: unknowns[j] for j in tears}
    for r, j in order:
        e = ca.substitute(rows[r], ca.vertcat(*syms), ca.vertcat(*vals)) if syms else rows[r]
        value[j] = -ca.substitute(e, unknowns[j], ca.SX(0)) / ca.jacobian(e, unknowns[j])
        syms.append(unknowns[j])
        vals.append(value[j])
    res = ca.vertcat(*[rows[r] for r, in residual])
    if syms:
        res = ca.substitute(res, ca.vertcat(*syms), ca.vertcat(*vals))
    return tears, res, ca.vertcat(*[value[j] for j in range(n)])


def _linear_solution(g: ca.SX, z: ca.SX, A: ca.SX, b: ca.SX, guess=None, largest: int = SYMBOLIC_SOLVE_MAX):
    """z solving the linear block g = A z + b = 0 symbolically, or None where the system left
    to eliminate has more than ``largest`` unknowns (it is then solved at run time); with
    ``guess`` (coefficients that change in a run), where the system is singular the solution
    nearest ``guess`` (:func:`_or_nearest`). A block of more than :data:`TEAR_LINEAR_MIN`
    unknowns, or too large to eliminate, is torn first (:func:`_tear`: the others follow one by
    one, by constant pivots, the same in every mode) where that leaves at most half of them:
    only the tearing variables' system is eliminated, and it is singular where the block is.
    Eliminated whole, with its nearest solution beside it, a rectifier bridge's 32 unknowns
    next to a machine's stator made a right-hand side of 42 000 operations (6 000 torn)."""
    n = z.numel()
    if n > TEAR_LINEAR_MIN or n > largest:
        torn, residual, whole = _tear(ca.vertsplit(g), ca.vertsplit(z))
        if not torn:
            return whole
        if len(torn) <= min(n // 2, largest):
            t = ca.vertcat(*[z[i] for i in torn])
            J = ca.jacobian(residual, t)
            r0 = ca.substitute(residual, t, ca.SX.zeros(t.sparsity()))
            sol = -ca.solve(J, r0) if len(torn) > 1 else -r0 / J
            if guess is not None:
                sol = _or_nearest(sol, J, r0, np.asarray(guess)[torn])
            return ca.substitute(whole, t, sol)
    if n > largest:
        return None
    sol = -ca.solve(A, b) if n > 1 else -b / A
    return _or_nearest(sol, A, b, guess) if guess is not None else sol


def _or_nearest(sol: ca.SX, A: ca.SX, b: ca.SX, guess) -> ca.SX:
    """``sol`` of A z + b = 0, or where A is singular (a junction of massless pipes at zero
    flow: its enthalpy appears only multiplied by the flows) the least-squares solution nearest
    the start values: the part of z the equations do not fix stays there, as nothing reads it
    then but through a zero."""
    return ca.if_else(_all_finite(sol), sol, _nearest(A, b, guess, ca.solve))


def _nearest(A, b, guess, solve):
    """The least-squares solution of A z + b = 0 nearest ``guess`` (SX or MX; ``solve(M, r)``
    solves M x = r): Tikhonov's, regularised just enough that the normal equations are never
    singular."""
    g = ca.DM(guess)
    reg = 1e-12 * (1 + ca.sumsqr(A))
    return g - solve(ca.mtimes(A.T, A) + reg * type(A).eye(A.size2()), ca.mtimes(A.T, ca.mtimes(A, g) + b))


def _least_squares_step(J, r):
    """The step dz of J dz + r = 0 by least squares, with Tikhonov's term just large enough that
    directions J leaves free (singular values below 1e-12 of its largest column) take no step:
    Newton's step where J is regular. Solved in the augmented form [I J; J' -reg] [y; dz] =
    [-r; 0], whose condition is J's, not its square (the normal equations left a robot's
    initial system, rows of 1e8 beside rows of 1, stalled at a residual of 0.4)."""
    m, n = J.shape
    reg = 1e-24 * (1 + ca.mmax(ca.sum1(J * J)))
    if m == n == 1:          # (in closed form: a scalar loop's function still expands to SX)
        return -J * r / (J * J + reg)
    K = ca.blockcat([[type(J).eye(m), J], [J.T, -reg * type(J).eye(n)]])
    return _sparse_qr(K, ca.vertcat(-r, type(J).zeros(n, 1)))[m:]


def _sparse_qr(M, r):
    """M x = r by sparse QR, NaN or inf (not an exception) where M is singular."""
    return ca.solve(M, r, "qr", {"eps": -1.0})


def _all_finite(z):
    """Whether every entry of ``z`` is finite, as an expression (through the sum: a norm's fmax
    passes over NaN)."""
    s = ca.sum1(z)
    return ca.logic_and(s == s, ca.fabs(s) < np.inf)


def _run_time_solve(A: ca.MX, b: ca.MX, how: str, guess) -> ca.MX:
    """z of A z + b = 0 solved when the model runs (its coefficients change with a mode); with
    ``guess`` (a block singular in some mode), where A is singular the least-squares solution
    nearest it: a gear and its bearing both locked at rest share a torque the equations leave
    open (any split holds), as OpenModelica's total-pivot fallback takes it. Sparse QR is told
    not to refuse a pivot (its default fails the whole evaluation). A result is kept where it
    solves the block, its rows scaled to unit sum, with a size a regular matrix gives
    (|A| |z| <= 1e12 |b|, row by row); else the nearest solution where it solves the block
    (a singular block may have none: a junction whose ports are all closed), else NaN, which
    the event iteration and the solver report. Both solves are computed (a conditional that
    computes one keeps the right-hand side from being fused into SX), so only where a mode can
    make A singular: the second solve made a converter's calls 40 % slower."""
    rows = 1.0 / (ca.sum2(ca.fabs(A)) + 1e-300)       # (the checks in each row's own scale)
    An, bn = ca.mtimes(ca.diag(rows), A), b * rows
    solve = _sparse_qr if how == "qr" else (lambda M, r: ca.solve(M, r, how))

    def solves(z, size_max=True):
        size = ca.norm_inf(ca.mtimes(ca.fabs(An), ca.fabs(z)))
        scale = ca.norm_inf(bn)
        ok = ca.logic_and(_all_finite(z), ca.norm_inf(ca.mtimes(An, z) + bn) <= 1e-8 * (scale + size))
        return ca.logic_and(ok, size <= 1e12 * scale) if size_max else ok

    sol = -solve(A, b)
    if guess is None:
        return ca.if_else(solves(sol), sol, np.nan)
    nearest = _nearest(An, bn, guess, solve)
    return ca.if_else(solves(sol), sol, ca.if_else(solves(nearest, False), nearest, np.nan))


def _read(jac: ca.Sparsity) -> np.ndarray:
    """Which of an input's entries (the columns of its Jacobian's sparsity ``jac``) are read:
    from the column indices (made dense, EngineV6's block against all its inputs took more
    memory than there is)."""
    out = np.zeros(jac.size2(), bool)
    out[np.asarray(jac.get_triplet()[1], int)] = True
    return out


def _singular_in_a_mode(fa: ca.Function, at: np.ndarray, mode_at: list[int], n_prev: int,
                        samples: int = 48) -> bool:
    """Whether the block's matrix (``fa``'s first output; its inputs the unknowns solved before
    it, then the args, flat at ``at``) is singular for some values of the modes it reads (the
    args' entries ``mode_at``): at their start values, then every combination of 0 and 1 where
    they are few (else random ones), then draws among -1..3, the other entries near their start
    values (a gear and its bearing both locked)."""
    rng = np.random.default_rng(0)
    at = np.where(np.isfinite(np.asarray(at, float)), at, 1.0)
    sizes = [fa.nnz_in(i) for i in range(fa.n_in())]
    reads = np.concatenate([_read(fa.sparsity_jac(i, 0)) if sizes[i] else np.zeros(0, bool) for i in range(fa.n_in())])
    modes = np.asarray([k for k in np.asarray(mode_at, int) + n_prev if reads[k]], int)
    if not modes.size:
        return False
    combos = ([at[modes]] + ([np.array(c, float) for c in itertools.product((0.0, 1.0), repeat=len(modes))]
                             if len(modes) <= 6 else list(rng.integers(0, 2, (samples, len(modes))).astype(float)))
              + list(rng.integers(-1, 4, (samples, len(modes))).astype(float)))
    for k, combo in enumerate(combos):
        v = at.copy() if k == 0 else at * (1 + 0.1 * rng.standard_normal(at.shape)) + 0.01 * rng.standard_normal(at.shape)
        v[modes] = combo
        A = np.array(fa(*np.split(v, np.cumsum(sizes)[:-1]))[0])
        if np.all(np.isfinite(A)) and np.linalg.cond(A) > 1e12:
            return True
    return False


def _loop_solve(name: str, resid: ca.Function, guess, par: ca.MX, strict: bool = False,
                start: np.ndarray | None = None) -> ca.MX:
    """The solution of an algebraic loop 0 = resid(z, par): Newton's method from ``guess`` (the
    start values; in a run the last solution, then the start values ``start``); where it does
    not converge (it cycles between the branches of a piecewise law, such as an amplifier's
    output limit, or meets a singular Jacobian), Newton's method with a backtracking line
    search from the start values, then polished by Newton, and for one unknown a sign change
    next to ``guess`` bracketed and halved. The fallback is evaluated only when needed (a short-circuit conditional);
    everything stays C-generable.
    NaN where even the fallback leaves a residual above INIT_TOL (Newton's method can stop on
    a zero step at a singularity, sqrt(x) at x = 0, and return a wrong answer). ``strict`` (an
    initial system): the fallback always starts off the start values. ``start``: the start
    values where ``guess`` is another point (the last solution, in a run)."""
    quick = ca.rootfinder(f"{name}_newton", "fast_newton", resid, {**NEWTON_OPTS, "error_on_fail": False})
    z0 = ca.MX(ca.DM(guess)) if isinstance(guess, np.ndarray) else guess
    z1 = quick(z0, par)
    sx = _sx_residual(resid)      # (expanded once, for the tolerance and the Jacobian)
    met = _met(name, resid, sx)
    ok = met(z1, par, LOOP_TOL)
    if start is not None:
        # from the last solution; where Newton's method fails there, from the start values,
        # as without a last solution (a saturating core: a guess deep in saturation, left
        # behind by the flux, sends Newton's method away where 0 does not)
        z1 = _otherwise(ok, z1, lambda p: quick(ca.DM(start), p), par)
        ok = met(z1, par, LOOP_TOL)
    # an initial system singular in the mode the initial event iteration set (a robot at rest
    # with its bearings locked leaves twelve directions free): where Newton's damped steps do
    # not meet it, least-squares steps from the same start (first: EngineV6_analytic's start
    # needs Newton's; nor in a run's loops, where they stalled a saturating core's)
    step, step_ls, jac = _damped_step(name, resid, sx, least_squares=strict)
    polish = ca.rootfinder(f"{name}_polish", "fast_newton", resid, {**NEWTON_OPTS, "error_on_fail": False})

    def fallback(z0, par):
        # the initial system's fallback starts a hair off the start values: a start at a
        # singularity (a tank's T = H/(m*c) at m = 0) has no Newton step, the point next to it has.
        # A run's loops move all their unknowns off a start only where the law has no finite
        # derivative (|B|^n with n < 1 at B = 0), and where it is finite, the unknowns no equation
        # moves alone (a column of zeros: two fittings in series started at rest, dp = k m_flow^2
        # at m_flow = 0, had no Newton step). A start singular otherwise (its columns dependent,
        # none zero) stays the model's to resolve
        # (in a run, from the start values too: the fallback is then the one without a last solution)
        zf = z0 if start is None else ca.MX(ca.DM(start))
        off = zf + 1e-6 * (1 + ca.fabs(zf))
        if strict:
            z = off
        else:
            Jf = jac(zf, par)
            s = ca.sum1(ca.vec(Jf))
            dead = ca.sum1(ca.fabs(Jf)).T == 0
            z = ca.if_else(ca.logic_and(s == s, ca.fabs(s) < np.inf), ca.if_else(dead, off, zf), off)
        for _ in range(DAMPED_ITERATIONS):
            z = step(z, par)
        z2 = polish(z, par)       # (which fails where the Jacobian is singular: then z as it is)
        z2 = ca.if_else(_all_finite(z2), z2, z)
        if step_ls is not None:
            def by_least_squares(z, par):
                for _ in range(DAMPED_ITERATIONS):
                    z = step_ls(z, par)
                return z
            z2 = _otherwise(met(z2, par, INIT_TOL), z2, by_least_squares, off, par)
        if z0.numel() == 1:
            # one unknown: a sign change, then the root inside it (a Newton method with a line
            # search stops at a local minimum of |r|, where an amplifier's branch has just ended)
            z2 = _otherwise(met(z2, par, INIT_TOL), z2, lambda a, p: polish(_bracketed(resid, a, p), p), z0, par)
        else:
            z2 = _otherwise(met(z2, par, INIT_TOL), z2, lambda a, p: _branchwise(name, resid, a, p, met), zf, par)
        # NaN, not an exception, where no solution is found: in a run the integrator then retries
        # with a shorter step (a rectifier's diodes switching: the next point is found from nearer)
        return ca.if_else(met(z2, par, INIT_TOL), z2, np.nan * ca.DM.ones(z2.shape))
    return _otherwise(ok, z1, fallback, z0, par)


def _otherwise(cond: ca.MX, value: ca.MX, fallback, *args) -> ca.MX:
    """``value`` where ``cond`` holds, else ``fallback(*args)``, evaluated only then. CasADi's
    short-circuit if_else builds each branch from the expression's free symbols, so a value
    computed before it is computed again inside the branch, and every nesting doubles the cost
    (a fluid model's loop solve, its fallbacks nested five deep: 18 s an evaluation); here
    ``value`` is passed into the branch."""
    args = [ca.MX(a) for a in args]
    syms = [ca.MX.sym(f"a{k}", a.sparsity()) for k, a in enumerate(args)]
    v = ca.MX.sym("v", value.sparsity())
    keep = ca.Function("f_keep", [v, *syms], [v])       # (f_: a branch, to expanded_size)
    other = ca.Function("f_otherwise", [v, *syms], [ca.MX(fallback(*syms))])
    return ca.Function.if_else("switch", keep, other)(cond, value, *args)


def _branchwise(name: str, resid: ca.Function, z0, par: ca.MX, met) -> ca.MX:
    """A solution of a loop with a few branches (comparisons), found on each combination of
    them in turn: Newton's method on the law with its comparisons fixed, from ``z0``, until
    one meets the loop's own residual (the branches it was solved on are then the ones it is
    on). A differential amplifier's loop (six tearing variables, its output limits moving with
    a floating ground) sends Newton's method from saturated to saturated, never trying the
    linear branch its solution is on. NaN where none does, or the loop has none or too many."""
    nan = np.nan * ca.DM.ones(resid.size1_in(0))
    if not resid.is_a("SXFunction"):
        return nan
    T, P = ca.SX.sym("t", resid.sparsity_in(0)), ca.SX.sym("p", resid.sparsity_in(1))
    cmps = _replay(resid, [T, P])[1]
    if not 0 < len(cmps) <= BRANCHES_MAX:
        return nan
    z = ca.MX(nan)
    for j, law in enumerate(_branch_laws(resid, [T, P], len(cmps))):
        fixed = ca.Function(f"{name}_branch{j}", [T, P], [law])
        solve = ca.rootfinder(f"{name}_on{j}", "fast_newton", fixed, {**NEWTON_OPTS, "error_on_fail": False})
        z = _otherwise(met(z, par, INIT_TOL), z, solve, z0, par)
    return z


def _bracketed(resid: ca.Function, z0: ca.MX, par: ca.MX) -> ca.MX:
    """A root of the scalar resid(z, par) = 0 near ``z0``: points ever farther on either side
    until the sign differs from r(z0)'s (``BRACKET_STEPS`` each way, out to 1e9 x (1 +
    |z0|)), then that interval halved (``BISECTIONS`` times). Each evaluation after the root is
    bracketed, or after it is found, is skipped; NaN where no sign change is found."""
    r0 = resid(z0, par)
    h = 1e-3 * (1 + ca.fabs(z0))
    found, lo, hi = ca.MX(0), z0, z0
    for j in range(BRACKET_STEPS):
        for side in (1.0, -1.0):
            near, far = z0 + side * h * (4.0 ** (j - 1) if j else 0.0), z0 + side * h * 4.0 ** j
            r = _otherwise(found, r0, resid, far, par)
            new = ca.logic_and(ca.logic_not(found), ca.logic_and(r * r0 <= 0, r == r))
            lo, hi = ca.if_else(new, near, lo), ca.if_else(new, far, hi)
            found = ca.logic_or(found, new)
    r_lo = r0 * 1.0
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        r = resid(mid, par)
        same = r * ca.sign(r_lo) > 0
        lo, r_lo, hi = ca.if_else(same, mid, lo), ca.if_else(same, r, r_lo), ca.if_else(same, hi, mid)
    return ca.if_else(found, 0.5 * (lo + hi), np.nan)


def _met(name: str, resid: ca.Function, sx):
    """(z, par, tol) -> whether the loop's residual is within ``tol``, or, row by row, within ``tol``
    times 1 + ROUNDING x (the sum of the row's terms' magnitudes): a thousand rounding errors
    of its largest terms where that is more (a drum's energy balance, U = m h - p V with U near
    1e11 J, is met to 1e-5 at best, never to an absolute 1e-9). Newton's method still iterates
    on the residual itself: scaled, it stops early on a diode's exp() terms, and the run's
    right-hand side turns noisy. ``sx``: :func:`_sx_residual`'s."""
    if sx is None:                # (solves of its own, or too large in SX): absolute only
        return lambda z, par, tol: _within(resid(z, par), tol)
    zs, ps, r = sx
    size = ca.vertcat(*[1 + ROUNDING * sum(ca.fabs(a) for a in _terms(e)) for e in ca.vertsplit(r)])
    scaled = ca.Function(f"{name}_scaled", [zs, ps], [r, r / size])

    def met(z, par, tol):
        r, rs = scaled(z, par)
        return ca.logic_or(_within(r, tol), _within(rs, tol))
    return met


def _sx_residual(resid: ca.Function):
    """(z, p, resid(z, p)) on SX symbols, or None where ``resid`` holds solves (MX only) or its
    calls would expand past EXPAND_TRY_MAX instructions: each call of a function is inlined whole,
    and a water property function called per use (IF97's, in a closed steam volume's initial
    system) grows to tens of GB."""
    if expanded_size(resid) > EXPAND_TRY_MAX:
        return None
    try:
        zs, ps = ca.SX.sym("z", resid.size1_in(0)), ca.SX.sym("p", resid.size1_in(1))
        return zs, ps, resid(zs, ps)
    except RuntimeError:
        return None


def _terms(e: ca.SX) -> list:
    """The terms of a sum (of differences and negations), as a list."""
    out, todo = [], [e]
    while todo:
        a = todo.pop()
        if a.is_op(ca.OP_ADD) or a.is_op(ca.OP_SUB):
            todo += [a.dep(0), a.dep(1)]
        elif a.is_op(ca.OP_NEG):
            todo.append(a.dep(0))
        else:
            out.append(a)
    return out


def _within(r, tol: float):
    """max |r| <= tol, false where r holds NaN (CasADi's mmax skips NaN: a Newton solve that
    failed to NaN would pass for converged and its fallback never run)."""
    return ca.logic_and(ca.mmax(ca.fabs(r)) <= tol, ca.sumsqr(r) <= r.numel() * tol ** 2)


def _damped_step(name: str, resid: ca.Function, sx, least_squares: bool = False):
    """(one step of Newton's method with backtracking: the longest of 1, 1/2, 1/4, ... that
    decreases |r|^2 enough (Armijo), the shortest when none does; with ``least_squares`` the
    same step from the least-squares step, else None; the Jacobian they use, in SX where
    ``sx``, :func:`_sx_residual`'s, has the residual)."""
    z, par = ca.MX.sym("z", resid.size1_in(0)), ca.MX.sym("par", resid.size1_in(1))
    if sx is not None:
        zs, ps, rs = sx
        jac = ca.Function(f"{name}_jac", [zs, ps], [ca.jacobian(rs, zs)])
    else:                      # (solves of inner loops, an initial system, or too large): in MX
        jac = ca.Function(f"{name}_jac", [z, par], [ca.jacobian(resid(z, par), z)])
    r = resid(z, par)
    # where the Jacobian is singular, the least-squares step (a pipe closed at both ends by dry
    # tank ports: its pressure is any that its static head allows, and Newton's step is
    # infinite). Sparse QR is told not to refuse a pivot: its default failed the whole
    # evaluation (TanksWithOverflow's update had no value at all)
    J = jac(z, par)
    # (the least-squares solution of J dz + r = 0 nearest dz = 0: already the step, downhill)
    nearest = _nearest(J, r, np.zeros(z.shape), _sparse_qr)
    f0 = ca.dot(r, r)

    def alpha(j, z, dz, par, f0):
        """The longest of 1/2^j, 1/2^(j+1), ... that decreases |r|^2 enough, the next one
        tried only where this one does not (mostly one or two residuals a step, not twelve)."""
        a = 0.5 ** j
        if j == LINE_SEARCH_STEPS - 1:
            return ca.MX(a)
        ra = resid(z + a * dz, par)
        return _otherwise(ca.dot(ra, ra) <= (1 - 1e-4 * a) * f0, ca.MX(a),
                          lambda *args: alpha(j + 1, *args), z, dz, par, f0)
    done = ca.dot(r, r) <= LOOP_TOL ** 2     # converged: the rest of the steps cost one residual

    def stepping(first, fname):
        dz = ca.if_else(_all_finite(first), first, nearest)
        body = ca.Function(f"{fname}_ls", [z, par], [ca.if_else(_all_finite(dz), z + alpha(0, z, dz, par, f0) * dz, z)])
        return ca.Function(f"{fname}_step", [z, par], [ca.if_else(done, z, body(z, par), True)])
    # (least squares: see _least_squares_step, where sparse QR's step, tiny pivots kept, is
    # finite but runs off along the directions a singular J leaves free)
    step_ls = stepping(_least_squares_step(J, r), f"{name}_lsq") if least_squares else None
    return stepping(-_sparse_qr(J, r), name), step_ls, jac


def build_ode(dae: Dae, name: str = "model") -> Ode:
    """Index reduction + causalisation + initialisation: the model's explicit ODE (a pure
    function of ``dae``; a hybrid model's discrete part included)."""
    dae, homotopic = homotopy.split(revealed(dae))
    ode = with_start_guesses(_hybrid(dae, name, homotopic) if dae.hybrid else _build(dae, name, homotopic))
    if ode.init_unmet > INIT_TOL:
        log.warning("the initial equations are not all met at the initial state found (largest "
                    "residual %.3g at the model's parameter values)", ode.init_unmet)
    return ode


def _build(dae: Dae, name: str = "model", homotopic=None, select: bool = True, inner: bool = False) -> Ode:
    """The continuous model's ODE (``homotopic``: see :func:`homotopy.split`; ``select``: see
    :func:`reduce_index`). ``inner``: the continuous part of a hybrid model, whose functions
    :func:`_hybrid` wraps and expands again: left in MX (expanded here too, a heat
    exchanger's took 47 of its 400 CPU-s)."""
    own, given = dae.residual, dae
    semi, state_to_orig, invariants, index = reduce_index(dae, select)
    moved = _preferred_states(dae, semi, state_to_orig)
    if moved is not dae:
        reduced = reduce_index(moved, select)
        # (kept where index reduction adds no more states than were preferred: a drum's
        # pressure made a state brought its saturation properties as five more, integrated
        # beside it, and a run 700x slower)
        n_moved = moved.x.numel() - dae.x.numel()
        if reduced[0]["x"].numel() - semi["x"].numel() - n_moved <= n_moved:
            dae = moved
            semi, state_to_orig, invariants, index = reduced
    # (the residual with homotopy's lambda has the rows of semi's where those are the model's own)
    homotopic = homotopic if homotopic is not None and semi["alg"] is own else None
    xs, zs = semi["x"], semi["z"]
    up = semi["p"]
    nu = dae.u.numel()
    orig = state_to_orig(xf=xs, zf=zs)
    x_impl, z_orig = orig["x_impl"], orig["z"]
    if semi.get("selected"):
        dae = _fixed_kept(dae, xs)

    # start values of the semi-explicit unknowns (used as Newton guesses and pins)
    start_fun = ca.Function("start", [dae.p], [dae.x_start, dae.z_start])
    x0_nom, z0_nom = (np.array(v).ravel() for v in start_fun(dae.p_values))
    to_orig = dict(zip(map(str, ca.vertsplit(dae.x)), x0_nom))
    to_orig.update(zip(map(str, ca.vertsplit(dae.z)), z0_nom))
    z_guess = np.array([to_orig.get(str(s), 0.0) for s in ca.vertsplit(zs)])

    t = semi["t"]
    modes = ca.vertcat(*[dae.p[i] for i, n in enumerate(dae.p_names) if n.startswith("$")])
    u0, p0 = np.asarray(dae.u_start, float).ravel(), np.asarray(dae.p_values, float)
    xs0 = np.array([to_orig.get(str(s), 0.0) for s in ca.vertsplit(xs)])
    zfun, n_nl, newton, cross_ops = causalise(semi["alg"], zs, [xs, up, t], z_guess, modes,
                                              guess=ca.SX.sym("g", zs.numel()),
                                              nominal=[xs0, np.concatenate([u0, p0]), np.zeros(1)],
                                              homotopic=homotopic)
    X, U, P0, T = (ca.MX.sym(n, k) for n, k in
                   (("x", xs.numel()), ("u", nu), ("p", dae.p.numel()), ("t", 1)))
    # a model with loops: a run's functions take the loops' guesses and the comparisons their
    # branches were on after the parameters (the engine passes the last solution's: Ode.warm);
    # the initial system's start from the start values
    npar, nz, nh = dae.p.numel(), zs.numel(), zfun.size1_in(4)
    ng = nz + nh if n_nl else 0
    P = ca.MX.sym("p", npar + ng) if ng else P0
    Pu, G, H = (P[:npar], P[npar:npar + nz], P[npar + nz:]) if ng else (P, ca.DM(z_guess), ca.DM.zeros(nh))
    UP = ca.vertcat(U, Pu)
    Z, z_free, cmp_now, branch = zfun(X, UP, T, G, H)
    nb = branch.numel() if ng else 0      # an event where a loop would change its branch
    # (x' apart from the checks: an SX function computes all its outputs at every call, and the
    # algebraic residual re-evaluates every equation: 386 000 instructions of IF97 in a pump's)
    sx_fun = ca.Function("sx", [xs, zs, up, t], [semi["ode"]])
    checks_fun = ca.Function("sx_checks", [xs, zs, up, t],
                             [semi["alg"], invariants_in(invariants, dae, x_impl, z_orig)])
    xdot, (g, inv) = sx_fun(X, Z, UP, T), checks_fun(X, Z, UP, T)
    zero = ca.DM.zeros(1, 1)
    absmax = (lambda v: ca.mmax(ca.fabs(v)) if v.numel() else zero)

    # every named variable of the original model, as a function of the ODE's arguments
    probe_names = list(dae.exprs)
    exprs = ca.vertcat(*[dae.exprs[n] for n in probe_names])
    # der() of the original states: read by initial equations such as der(x) = 0 (steady
    # state) and by variables such as the MSL hysteresis' ascending = der(H) > 0
    dxi_sx = orig["dx_impl"] if semi.get("selected") else ca.jtimes(x_impl, xs, semi["ode"])
    dxi_fun = ca.Function("dxi", [xs, zs, up, t], [dxi_sx])
    probe_sx = ca.Function("probe_sx", [dae.x, dae.z, dae.u, dae.p, dae.t, dae.dx], [exprs])
    orig_fun = ca.Function("orig", [xs, zs], [x_impl, z_orig])

    def probe_at(X, Z, U, P, T):
        return probe_sx(*orig_fun(X, Z), U, P, T, dxi_fun(X, Z, ca.vertcat(U, P), T))

    XI, ZI = orig_fun(X, Z)
    dXI = dxi_fun(X, Z, UP, T)
    probe_all = probe_at(X, Z, U, Pu, T)
    y_idx = [probe_names.index(o) for o in dae.outputs]

    args, names = [X, U, P, T], ["x", "u", "p", "t"]
    mk = (lambda fname, outs: ca.Function(fname, args, outs, names, ["out"]))
    ode = mk("ode", [xdot])
    out = mk("out", [probe_all[y_idx] if y_idx else ca.MX(0, 1)])
    alg_res = mk("alg_res", [absmax(g)])
    drift = mk("drift", [absmax(inv)])
    probe = mk("probe", [probe_all])
    crossings = None
    if dae.relations.numel() or nb:
        rel_sx = ca.Function("rel", [dae.x, dae.z, dae.u, dae.p, dae.t, dae.dx], [dae.relations])
        crossings = mk("zero", [ca.vertcat(rel_sx(XI, ZI, U, Pu, T, dXI), branch if nb else ca.MX(0, 1))])
        crossings = compact(crossings) if n_nl and not inner else crossings
    y_all = probe_all[y_idx] if y_idx else ca.MX(0, 1)
    checks = ca.Function("checks", args, [y_all, absmax(g), absmax(inv)], names, ["y", "res", "drift"])

    x_names = semi_state_names(xs, dae)
    # the initial system in all the unknowns, where the algebraic ones are not solved for
    init_sx = ca.substitute(dae.init_residual, ca.vertcat(dae.x, dae.dx, dae.z),
                            ca.vertcat(x_impl, dxi_sx, z_orig))
    wish = _preferred(dae)
    wish_sx = wish(x_impl, z_orig, dae.u, dae.p, t, dxi_sx)
    invariant_rows = invariants_in(invariants, dae, x_impl, z_orig)
    joint = (zs, semi["alg"], ca.vertcat(invariant_rows, init_sx, wish_sx), xs, up, t)
    # (the initial system's loops from the start values)
    zargs = [X, ca.vertcat(U, P0), T, *((ca.DM(z_guess), -ca.DM.ones(nh)) if ng else (G, H))]
    # (a walk only where the initial equations read der(): without, its steps are the solve itself)
    pseudo = (lambda: _pseudo_transient_rows(dae, joint, invariant_rows, (x_impl, dxi_sx, z_orig),
                                             X, U, P0, T, zfun, zargs)) \
        if dae.dx.numel() and ca.depends_on(dae.init_residual, dae.dx) else None
    start, init_start, unmet = _initialiser(dae, xs, X, U, P0, T, _initial_rows(joint, zfun, zargs),
                                     joint[2].numel() - wish_sx.numel(), x_names, joint, pseudo)
    init = ca.Function("init", [U, P0, T], [init_start(U, P0, T, start(P0))], ["u", "p", "t"], ["x0"])
    if semi.get("selected") and _finite(lambda u: init(u, p0, 0.0), u0) is None:
        # no consistent start in the selected states (six coordinates of point masses that
        # make one rigid body, its rotation found from them by Newton's method): every
        # differentiated variable a state, the constraints checked as invariants
        log.debug("%s: no initial state in the selected states; the constraints dropped instead", name)
        return _build(given, name, homotopic, select=False, inner=inner)
    if ng:
        init, start, init_start = (_guesses_ignored(f, ng) for f in (init, start, init_start))
    loops, given = _newton_functions(newton, args, names, sx_fun, probe_at, U, Pu, G, H)
    # SX evaluates faster than the MX call graph where there is no Newton or QR solve in it; a
    # loop's Newton solve expands too (a torn loop of one unknown), but as every iteration and
    # the fallback unrolled, all evaluated at each call, and its Jacobian through them all: the
    # Cauer example takes 21 CPU-s so, 12 with the loop solved in MX
    if not n_nl and not inner:
        ode, out, alg_res, drift, probe, checks, crossings = expanded_together(
            ode, out, alg_res, drift, probe, checks, crossings)
        init, start, init_start = map(expanded, (init, start, init_start))
    return Ode(
        x_names=x_names, u_names=list(dae.u_names), p_names=list(dae.p_names),
        y_names=list(dae.outputs), p_values=dae.p_values.copy(), u_start=dae.u_start.copy(),
        ode=ode, out=out, alg_res=alg_res, drift=drift, init=init, probe=probe, checks=checks,
        probe_names=probe_names, index=index, nonlinear_blocks=n_nl,
        time_events=tuple(dae.time_events), zero=crossings, start=start, init_start=init_start,
        init_unmet=unmet,
        events=({"relation_ops": [*dae.relation_ops, *cross_ops], **({"branches": nb} if nb else {})}
                if dae.relation_ops or nb else None),
        loops=loops, given=given,
        # (no comparison held before the first solve: -1 is neither true nor false)
        solved=mk("solved", [ca.vertcat(z_free, cmp_now)]) if ng else None,
        guess0=np.concatenate([z_guess, -np.ones(nh)]) if ng else None,
    )


def initial_state(ode: Ode, p_cols) -> ca.Function:
    """(u, p, t) -> (x0, d x0 / d p[:, p_cols]): the initial equations and their derivative in
    the parameters ``p_cols`` (where a parameter that only sets a state, s0 in M.s = s0, acts).
    Raises RuntimeError for an initial solve that CasADi cannot differentiate."""
    U, P, T = ode.init.mx_in()
    x0 = ode.init(U, P, T)
    return ca.Function("dx0", [U, P, T], [x0, ca.densify(ca.jacobian(x0, P)[:, p_cols])])


def differentiable(ode: Ode, which: str = "ode", p_cols=None) -> ca.Function:
    """``ode.ode`` (x') or ``ode.out`` (y) for a caller that differentiates it (an integrator's
    Newton method and forward sensitivities, the outputs' sensitivities): the function itself,
    or, for a model with algebraic loops, the function with its Jacobian from the Newton form
    (one loop solve and SX algebra, instead of the loop solver's own derivatives through the MX
    graph: several times faster). ``p_cols``: the parameters whose derivatives the caller
    reads (None: all); the others' are given as zero. CasADi evaluates the whole Jacobian for
    any block of it, and the block in 200 parameters costs 4x the one in 41 states (a machine
    fed by a diode bridge) where a run without sensitivities reads none of it."""
    fun = getattr(ode, which)
    where = {n: k for k, n in enumerate(ode.probe_names)}
    args, names = fun.mx_in(), fun.name_in()
    if ode.loops is None:
        # an SX function's Jacobian as one SX expression: CVODES otherwise differentiates the
        # call in forward sweeps, 6x the cost (a machine fed by a diode bridge: 4.5 ms a
        # Jacobian against 0.7)
        if not fun.is_a("SXFunction"):
            return fun
        a_sym = fun.sx_in()
        value, ZL, zl = fun.call(a_sym)[0], [], []
    elif which == "out" and not all(n in where for n in ode.y_names):
        return fun
    else:
        sym = ca.SX if ode.given.is_a("SXFunction") else ca.MX    # (MX: it holds a run-time solve)
        a_sym = [sym.sym(n, a.sparsity()) for n, a in zip(names, args)]
        ZL = [sym.sym("zl", ode.given.size1_in(4))]
        xdot, probe = ode.given(*a_sym, *ZL)
        value = xdot if which == "ode" else (probe[[where[n] for n in ode.y_names]] if ode.y_names else sym(0, 1))
        zl = [ode.loops(*args)]
    x, u, p, t = a_sym
    blocks = [ca.jacobian(value, x), ca.jacobian(value, u), _jacobian_in(value, p, p_cols), ca.jacobian(value, t)]
    jac = ca.Function("given_jac", [*a_sym, *ZL], blocks)
    oname = fun.name_out(0)
    out = ca.MX.sym(oname, fun.sparsity_out(0))
    custom = ca.Function(f"jac_{which}_newton", [*args, out], jac(*args, *zl),
                         [*names, oname], [f"jac_{oname}_{n}" for n in names])
    # (call it on symbols of your own: on its own inputs CasADi inlines it, custom Jacobian lost)
    return ca.Function(f"{which}_newton", args, fun.call(args), names, [oname],
                       {"custom_jacobian": custom, "jac_penalty": 0})


def _jacobian_in(value, p, cols=None):
    """d value / d p in the columns ``cols`` (None: all), zero in the others."""
    if cols is None:
        return ca.jacobian(value, p)
    cols = sorted(int(c) for c in cols)
    if not cols:
        return type(value)(value.numel(), p.numel())
    pick = ca.DM(ca.Sparsity.triplet(len(cols), p.numel(), list(range(len(cols))), cols), 1.0)
    if isinstance(value, ca.SX):           # SX: differentiated in those entries alone
        return ca.mtimes(ca.jacobian(value, p[cols]), pick)
    return ca.mtimes(ca.mtimes(ca.jacobian(value, p), pick.T), pick)


def with_start_guesses(ode: Ode) -> Ode:
    """``ode`` whose functions take the loops' guesses after the parameters, as one whose
    loops start from the start values, with the former as its ``warm``."""
    if ode.guess0 is None:
        return ode
    import dataclasses

    fixed = {f.name: _guesses_fixed(getattr(ode, f.name), ode.guess0) for f in dataclasses.fields(ode)
             if isinstance(getattr(ode, f.name), ca.Function) and f.name != "solved"}
    events, nb = ode.events, (ode.events or {}).get("branches", 0)
    if nb:      # a branch's end is an event of a run alone: an FMU's loops start from the start values
        ops = events["relation_ops"][:-nb]
        zero = fixed["zero"]
        args = zero.mx_in()
        kept = ca.Function("zero", args, [zero.call(args)[0][:-nb]], zero.name_in(), zero.name_out())
        fixed["zero"] = _same_kind(zero, kept) if ops else None
        events = {**{k: v for k, v in events.items() if k != "branches"}, "relation_ops": ops}
        events = None if events == {"relation_ops": []} else events
    return dataclasses.replace(ode, **fixed, solved=None, guess0=None, events=events, warm=ode)


def _guesses_fixed(f: ca.Function, guess0: np.ndarray) -> ca.Function:
    """``f`` with the tail of its argument p fixed at ``guess0``."""
    return _same_kind(f, _with_p(f, -len(guess0), lambda p: ca.vertcat(p, ca.DM(guess0))))


def _same_kind(f: ca.Function, g: ca.Function) -> ca.Function:
    """``g``, a rewrapping of ``f``, expanded where ``f`` was SX."""
    return rewrapped(g) if f.is_a("SXFunction") else g


def _guesses_ignored(f: ca.Function, ng: int) -> ca.Function:
    """``f`` taking ``ng`` guesses after its parameters, which it does not read."""
    n = f.size1_in(f.name_in().index("p"))
    return _with_p(f, ng, lambda p: p[:n])


def _with_p(f: ca.Function, grown: int, old_p) -> ca.Function:
    """``f`` whose argument p is ``grown`` entries longer (shorter if negative), the p it
    had being ``old_p(new p)``."""
    args, i = f.mx_in(), f.name_in().index("p")
    p = ca.MX.sym("p", args[i].numel() + grown)
    call = [old_p(p) if k == i else a for k, a in enumerate(args)]
    return ca.Function(f.name(), [p if k == i else a for k, a in enumerate(args)], f.call(call),
                       f.name_in(), f.name_out())


def _newton_functions(newton, args, names, sx_fun, probe_at, U, P, G, H):
    """(loops: (x, u, p, t) -> zl, given: (x, u, p, t, zl) -> (x', every probe)) from
    :func:`causalise`'s Newton form, or (None, None): ``given`` at the loops' solution is the
    model, with the loops' implicit derivatives and none in zl (an SX function). ``P``: the
    parameters, ``G`` the loops' guesses and ``H`` the comparisons held (the tail of p)."""
    if newton is None:
        return None, None
    loops_fun, z_newton = newton
    X, T = args[0], args[3]
    UP = ca.vertcat(U, P)
    ZL = ca.MX.sym("zl", z_newton.size1_in(4))
    Zg = z_newton(X, UP, T, G, ZL)
    xdot = sx_fun(X, Zg, UP, T)
    loops = ca.Function("loops", args, [loops_fun(X, UP, T, G, H)], names, ["zl"])
    given = ca.Function("given", [*args, ZL], [xdot, probe_at(X, Zg, U, P, T)], [*names, "zl"], ["xdot", "probe"])
    return loops, expanded(given)


def _demoted_read(dae: Dae, kept: list[str]) -> bool:
    """Whether an original state that state selection made algebraic (not in ``kept``) is
    reinit() or read through pre(): the event handling holds the original states that are
    states (then every differentiated variable is kept a state instead)."""
    kept = set(kept)
    gone = [k for k, n in enumerate(dae.x_names) if n not in kept]
    if not gone:
        return False
    nx = len(dae.x_names)
    # (the symbols read, once: an engine leaves 1 400 of its states, each a walk of the model)
    read = {v.element_hash() for v in ca.symvar(ca.vertcat(
        dae.residual, dae.init_residual, dae.d_update, dae.x_reinit, dae.relations, dae.asserts,
        *dae.exprs.values()))} if dae.x_pre.numel() == nx else set()
    return any((dae.x_reinit.numel() == nx and not ca.is_equal(dae.x_reinit[k], dae.x[k]))
               or dae.x_pre[k].element_hash() in read for k in gone)


def _hybrid(dae: Dae, name: str, homotopic=None, retried: bool = False) -> Ode:
    """A hybrid model's ODE: the discrete variables (and pre(), the flags) are parameters of the
    continuous model while it is causalised; its functions then take them from the end of the
    state vector. The update at an event and the asserts are read through the same solve of the
    algebraic equations as every other variable (hidden entries of ``exprs``). ``retried``: the
    held relations already start as the start values make them (:func:`_relations_at_start`)."""
    nd, nx0, nf, nzp = dae.d.numel(), dae.x.numel(), dae.flags.numel(), dae.z_pre.numel()
    extra = ca.vertcat(dae.d, dae.d_pre, dae.x_pre, dae.flags, dae.z_pre)
    exprs = dict(dae.exprs)
    hidden = {"pre": [f"$pre[{k}]" for k in range(nzp)],
              "update": [f"$update[{k}]" for k in range(dae.d_update.numel())],
              "reinit": [f"$reinit[{k}]" for k in range(dae.x_reinit.numel())],
              "assert": [f"$assert[{k}]" for k in range(dae.asserts.numel())]}
    for key, e in (("update", dae.d_update), ("reinit", dae.x_reinit), ("assert", dae.asserts)):
        exprs.update(zip(hidden[key], ca.vertsplit(e)))
    # the discrete variables' initial values may read time and inputs (an initial algorithm's
    # count := integer((time - startTime)/period)): taken at the start of each run
    d0_fun = ca.Function("d0", [dae.p, dae.u, dae.t], [dae.d_start]) if nd else None
    d0 = np.array(d0_fun(dae.p_values, dae.u_start, 0.0)).ravel() if nd else np.zeros(0)
    aug = dataclasses.replace(
        dae, p=ca.vertcat(dae.p, extra), p_names=[*dae.p_names, *[f"${k}" for k in range(extra.numel())]],
        p_values=np.concatenate([dae.p_values, d0, d0, np.zeros(nx0), np.eye(1, nf).ravel(), np.zeros(nzp)]),
        exprs=exprs,     # (the values at the start: initial() true)
        d=ca.SX(0, 1), d_names=[], d_start=ca.SX(0, 1), d_pre=ca.SX(0, 1), x_pre=ca.SX(0, 1), z_pre=ca.SX(0, 1),
        flags=ca.SX(0, 1), d_update=ca.SX(0, 1), x_reinit=ca.SX(0, 1), asserts=ca.SX(0, 1))
    inner = _build(aug, name, homotopic, inner=True)
    if _demoted_read(dae, inner.x_names):
        inner = _build(aug, name, homotopic, select=False, inner=True)
    if nd and not retried and inner.init_unmet > INIT_TOL:
        # the relations held false leave the initial equations unmet or without a solution:
        # held as the start values make them instead, where that does better
        seen = _relations_at_start(dae)
        other = _hybrid(seen, name, homotopic, retried=True) if seen is not None else None
        log.debug("%s: initial residual %.3g with the relations held false, %s as the start values "
                  "make them", name, inner.init_unmet, "-" if other is None else f"{other.init_unmet:.3g}")
        if other is not None and other.init_unmet < inner.init_unmet:
            return other
    nx = len(inner.x_names)
    pos = {n: j for j, n in enumerate(inner.x_names)}
    # reinit() and pre(x) of an original state: its place among the semi-explicit states
    where = [pos.get(n) for n in dae.x_names]
    for k, j in enumerate(where):
        if j is None and not ca.is_equal(dae.x_reinit[k], dae.x[k]):
            raise UnsupportedConstruct(f"model {name}: reinit() of {dae.x_names[k]}, a state index "
                                       "reduction replaced")
    # the loops' guesses: after the parameters, outside as inside
    npar, ng = len(dae.p_names), (0 if inner.guess0 is None else len(inner.guess0))
    nb = (inner.events or {}).get("branches", 0)
    X, D, U, P, T = (ca.MX.sym(n, k) for n, k in (("x", nx), ("d", nd), ("u", len(dae.u_names)),
                                                  ("p", npar + ng), ("t", 1)))
    Pu, G = (P[:npar], P[npar:]) if ng else (P, ca.MX(0, 1))
    XF = ca.vertcat(X, D)
    PRE, FL = ca.MX.sym("pre", nx + nd), ca.MX.sym("flags", nf)

    def orig(v):        # values of the original states from the semi-explicit ones
        return ca.vertcat(*[v[j] if j is not None else ca.MX(0) for j in where]) if nx0 else ca.MX(0, 1)

    def inner_p(D, D_pre, x_pre, flags, z_pre=None):     # the order of ``extra``
        return ca.vertcat(Pu, D, D_pre, x_pre, flags, ca.MX.zeros(nzp) if z_pre is None else z_pre, G)

    # (held: between events x' does not vary with the discrete values or pre(x); through a
    # loop's Newton solve, which reads every parameter, their derivatives can be NaN, and one
    # NaN column fails every Newton step of the integrator: a tank of IF97 water. Only where
    # the solver differentiates through that solve: without loops the functions are expanded
    # to SX, which inlines the hold; where the loops' Newton form gives the Jacobian, that
    # Jacobian with held values disagreed with the right-hand side's differences, and
    # DrumBoiler took 27 500 solver steps instead of 585)
    hold = _held if inner.nonlinear_blocks and inner.loops is None else (lambda v: v)
    DH = hold(D)
    PA = inner_p(DH, DH, hold(orig(X)), ca.MX.zeros(nf))
    names = inner.probe_names
    where_is = {n: j for j, n in enumerate(names)}
    idx = {key: [where_is[n] for n in hidden[key]] for key in hidden}
    visible = [j for j, n in enumerate(names) if not n.startswith("$")]
    args, io = [XF, U, P, T], ["x", "u", "p", "t"]

    expand = expanded if not inner.nonlinear_blocks else compact

    def mk(fname, outs, out_names=("out",)):       # (expanded at the end: see ``together``)
        return ca.Function(fname, args, outs, io, list(out_names))

    ode = mk("ode", [ca.vertcat(inner.ode(X, U, PA, T), ca.MX.zeros(nd))])
    probe_all = inner.probe(X, U, PA, T)
    y, res, drift = inner.checks(X, U, PA, T)
    update = None
    reinits = [k for k in range(nx0) if not ca.is_equal(dae.x_reinit[k], dae.x[k])]
    if nd or reinits:
        D_PRE = PRE[nx:] if nd else ca.MX(0, 1)
        z_pre = ca.MX(0, 1)
        if nzp:     # pre(z): z where the discrete variables had their pre() values
            z_pre = inner.probe(PRE[:nx], U, inner_p(D_PRE, D_PRE, orig(PRE[:nx]), FL), T)[idx["pre"]]
        PU = inner_p(D, D_PRE, orig(PRE[:nx]), FL, z_pre)
        after = inner.probe(X, U, PU, T)
        x_new = [X[j] for j in range(nx)]
        for k in reinits:
            x_new[where[k]] = after[idx["reinit"][k]]
        upd = ca.vertcat(*x_new, after[idx["update"]] if nd else ca.MX(0, 1))
        update = expand(ca.Function("update", [XF, U, P, T, PRE, FL], [upd],
                                    ["x", "u", "p", "t", "pre", "flags"], ["x_new"]))
    D0 = d0_fun(Pu, U, T) if nd else ca.MX(0, 1)
    # the initial system's parameters: the discrete starts, and initial() true (an equation
    # if initial() then ... holds there: the MSL's hysteresis starts with its slope at 0)
    initial_flags = ca.MX(ca.DM([1.0] + [0.0] * (nf - 1))) if nf else ca.MX(0, 1)

    def at_start(D):
        return inner_p(D, D, ca.MX.zeros(nx0), initial_flags)

    PA0 = at_start(D0)
    UPT = [U, P, T]
    init = ca.Function("init", UPT, [ca.vertcat(inner.init(U, PA0, T), D0)], ["u", "p", "t"], ["x0"])
    DI = ca.MX.sym("d", nd)
    init_discrete = ca.Function("init_discrete", [U, P, T, DI],
                                [inner.init(U, at_start(DI), T)],
                                ["u", "p", "t", "d"], ["x0"])
    S = ca.MX.sym("s", nx + nd)
    SD = S[nx:] if nd else ca.MX(0, 1)       # (an empty slice of MX is 1x0)
    D0s = d0_fun(Pu, dae.u_start, 0.0) if nd else ca.MX(0, 1)     # guesses: at t = 0, the inputs' starts
    PA0s = at_start(D0s)
    start = ca.Function("start", [P], [ca.vertcat(inner.start(PA0s), D0s)], ["p"], ["s"]) if inner.start else None
    init_start = (ca.Function("init_start", [U, P, T, S], [ca.vertcat(inner.init_start(
        U, at_start(SD), T, S[:nx]), SD)],
        ["u", "p", "t", "s"], ["x0"]) if inner.init_start else None)
    zero = mk("zero", [inner.zero(X, U, PA, T)]) if inner.zero is not None else None
    asserts = mk("asserts", [probe_all[idx["assert"]]]) if hidden["assert"] else None
    together = [ode, mk("out", [y]), mk("alg_res", [res]), mk("drift", [drift]), mk("probe", [probe_all[visible]]),
                mk("checks", [y, res, drift], ("y", "res", "drift")), zero, asserts]
    ode, out, alg_res, drift, probe, checks, zero, asserts = (
        expanded_together(*together) if expand is expanded else compact_together(*together))
    loops = given = None
    if inner.loops is not None:
        ZL = ca.MX.sym("zl", inner.given.size1_in(4))
        xdot_g, probe_g = inner.given(X, U, PA, T, ZL)
        loops = ca.Function("loops", args, [inner.loops(X, U, PA, T)], io, ["zl"])
        given = rewrapped(ca.Function("given", [*args, ZL], [ca.vertcat(xdot_g, ca.MX.zeros(nd)), probe_g[visible]],
                                      [*io, "zl"], ["xdot", "probe"]))
    return Ode(
        x_names=[*inner.x_names, *dae.d_names], u_names=list(dae.u_names), p_names=list(dae.p_names),
        y_names=list(dae.outputs), p_values=dae.p_values.copy(), u_start=dae.u_start.copy(),
        ode=ode, out=out, alg_res=alg_res, drift=drift, init=expand(init), probe=probe, checks=checks,
        probe_names=[names[j] for j in visible], index=inner.index, nonlinear_blocks=inner.nonlinear_blocks,
        time_events=tuple(dae.time_events), zero=zero,
        start=expand(start) if start is not None else None,
        init_start=expand(init_start) if init_start is not None else None,
        discrete=nd, update=update, init_discrete=expand(init_discrete), asserts=asserts,
        events={"clocks": [list(c) for c in dae.clocks], "flags": ["initial", "terminal"] +
                [f"tick{k}" for k in range(len(dae.clocks))], "asserts": [list(a) for a in dae.assert_info],
                "relation_ops": list((inner.events or {}).get("relation_ops", dae.relation_ops)),
                **({"branches": nb} if nb else {})},
        loops=loops, given=given,
        solved=expand(mk("solved", [inner.solved(X, U, PA, T)])) if ng else None, guess0=inner.guess0,
        init_unmet=inner.init_unmet,
    )


def _relations_at_start(dae: Dae) -> Dae | None:
    """``dae`` with its held relations started as the start values make them, where that
    differs from their default start (false); None where it does not. Held false, a vessel's
    regularFlow = fluidLevel >= portsData_height shut its ports, and a heating loop's steady
    initial system, chosen for shut ports, had no solution; other tools evaluate a relation
    from the values during the initialisation. Tried only where false leaves them unmet."""
    from .rumoca_frontend import HELD_PREFIX

    # (each read from its value at an event, in ``d_update``: the relations' own list keeps only
    # those on the unknowns, so a held relation's number is not its place there)
    held = [j for j, n in enumerate(dae.d_names) if n.startswith(HELD_PREFIX)]
    if not held:
        return None
    # (in the parameters, inputs and time, as the discrete starts are: taken at each run's start;
    # initial() true, as in the initial system's parameters)
    values = ca.vertcat(dae.x_start, dae.z_start, ca.SX.zeros(dae.dx.numel()), dae.d_start, dae.d_start,
                        dae.x_start, ca.SX.zeros(dae.z_pre.numel()), ca.DM(np.eye(1, dae.flags.numel()).ravel()))
    syms = ca.vertcat(dae.x, dae.z, dae.dx, dae.d, dae.d_pre, dae.x_pre, dae.z_pre, dae.flags)
    truth = ca.substitute(ca.vertcat(*[dae.d_update[j] for j in held]), syms, values)
    new = ca.vertsplit(dae.d_start)
    for n, j in enumerate(held):
        new[j] = truth[n]
    new = ca.vertcat(*new)
    at = ca.Function("d0", [dae.p, dae.u, dae.t], [dae.d_start, new])
    old_v, new_v = (np.array(v).ravel() for v in at(dae.p_values, dae.u_start, 0.0))
    if not np.all(np.isfinite(new_v)) or np.array_equal(old_v, new_v):
        return None
    return dataclasses.replace(dae, d_start=new)


def _held(v: ca.MX) -> ca.MX:
    """``v`` with a zero derivative."""
    if not v.numel():
        return v
    s = ca.SX.sym("v", v.sparsity())
    return ca.Function("held", [s], [s], {"is_diff_in": [False], "is_diff_out": [False]})(v)


def composed_checks(out: ca.Function, alg_res: ca.Function, drift: ca.Function) -> ca.Function:
    """``checks`` from the three functions (for models saved before it existed)."""
    args = out.mx_in()
    return ca.Function("checks", args, [out(*args), alg_res(*args), drift(*args)],
                       ["x", "u", "p", "t"], ["y", "res", "drift"])


def expanded(f: ca.Function) -> ca.Function:
    """``f`` in SX, its repeated subexpressions merged (see :func:`rewrapped`, :func:`merged`)."""
    return merged(rewrapped(f))


def rewrapped(f: ca.Function) -> ca.Function:
    """``f`` in SX where it expands, else :func:`fused`; not merged: for a wrapper that calls
    functions already expanded and merged once each, where merging again would find nothing
    (a room of moist air's 420 000 nodes, 2 s each time, twice in its compile and once at each
    load from the cache)."""
    try:
        return f.expand()
    except RuntimeError:    # holds a rootfinder or a run-time linear solver
        return fused(f)


def expanded_together(*fs: ca.Function | None) -> list:
    """``expanded`` of each of ``fs`` (None stays None), functions of the same arguments that
    read the same solve (x', the outputs, the checks, every variable): expanded and merged once,
    what they share computed once in each (one by one, a heat exchanger's seven took 41 CPU-s,
    most of it merging the same subexpressions again)."""
    live = [f for f in fs if f is not None]
    try:
        args = live[0].mx_in()
        whole = merged(ca.Function("together", args, [o for f in live for o in f.call(args)]).expand())
    except (IndexError, RuntimeError):      # (none, or one holds a solve: each as it expands)
        return [None if f is None else expanded(f) for f in fs]
    sx = whole.sx_in()
    outs = whole.call(sx)
    made = []
    for f in live:
        made.append(ca.Function(f.name(), sx, outs[:f.n_out()], f.name_in(), f.name_out()))
        outs = outs[f.n_out():]
    made = iter(made)
    return [None if f is None else next(made) for f in fs]


def merged(f: ca.Function) -> ca.Function:
    """SX ``f`` with its repeated subexpressions computed once, where it is large (index
    reduction and causalisation copy what the model's expressions share)."""
    if not f.is_a("SXFunction") or f.n_instructions() < CSE_MIN:
        return f
    args = f.sx_in()
    return ca.Function(f.name(), args, ca.cse(f.call(args)), f.name_in(), f.name_out())


def fused(f: ca.Function) -> ca.Function:
    """``f`` (MX: SX functions around run-time linear solves, in functions it calls) as a few SX
    functions around the same solves: each solve fed by one SX function of the inputs and the
    solves before it, the outputs from one more. Called block by block, a thyristor bridge's 45
    blocks and its one 15x15 solve took 17 us an evaluation of its right-hand side, nearly all of
    it the calls (5 us fused). ``f`` as it is where it holds a loop's Newton solve (fused so, a
    model read back from the compile cache could not be differentiated: CasADi's 'Duplicate'),
    more than FUSE_STAGES_MAX solves (each stage recomputes what those before it did), or a
    solve CasADi cannot redo.
    """
    if not f.is_a("MXFunction"):
        return f
    ins, outs, g = _inlined(f)
    if g is None:
        return f
    ops = [g.instruction_id(k) for k in range(g.n_instructions())]
    if any(op == ca.OP_CALL and not g.instruction_MX(k).which_function().is_a("SXFunction") for k, op in enumerate(ops)):
        return f
    work = [g.instruction_MX(k) for k, op in enumerate(ops) if op == ca.OP_SOLVE]
    if not work or len(work) > FUSE_STAGES_MAX:
        return f
    syms = [ca.MX.sym(f"s{k}", n.sparsity()) for k, n in enumerate(work)]
    try:
        stages = []
        for k, n in enumerate(work):
            deps = [n.dep(j) for j in range(n.n_dep())]
            stage = ca.Function(f"stage{k}", [*ins, *syms[:k]], ca.graph_substitute(deps, work[:k], syms[:k]) if k else deps)
            stages.append((n, deps, merged(stage.expand())))
        last = merged(ca.Function("stages_out", [*ins, *syms], ca.graph_substitute(outs, work, syms)).expand())
    except RuntimeError:         # (something else SX does not hold)
        return f
    args, done = f.mx_in(), []
    for n, deps, stage in stages:
        try:    # (the solve again on the stage's values: CasADi cannot redo some of its derivatives')
            done.append(ca.graph_substitute(n, deps, stage.call([*args, *done])))
        except RuntimeError:
            return f
    return ca.Function(f.name(), args, last.call([*args, *done]), f.name_in(), f.name_out())


def _inlined(f: ca.Function, rounds: int = 20):
    """(inputs, outputs, a Function of them) of MX ``f`` with every MX function it calls
    inlined, at any depth (the solves' nodes then the ones in the outputs' graph); the Function
    None past ``rounds`` levels."""
    ins = f.mx_in()
    outs = f.call(ins, True, False)
    for _ in range(rounds):
        g = ca.Function("flat", ins, outs)
        calls = [g.instruction_MX(k) for k in range(g.n_instructions()) if g.instruction_id(k) == ca.OP_CALL
                 and g.instruction_MX(k).which_function().is_a("MXFunction")]
        if not calls:
            return ins, outs, g
        old, new = [], []
        for n in calls:
            h = n.which_function()
            res = h.call([n.dep(j) for j in range(n.n_dep())], True, False)
            old += [n.get_output(i) for i in range(h.n_out())]
            new += res
        outs = ca.graph_substitute(outs, old, new)
    return ins, outs, None


def too_large_to_expand(f: ca.Function | None) -> bool:
    """Whether ``f`` is an MX function that :func:`expanded_size` estimates past
    EXPAND_TRY_MAX instructions expanded (a fluid's media calls, each inlined whole)."""
    return f is not None and not f.is_a("SXFunction") and expanded_size(f) > EXPAND_TRY_MAX


def compact(f: ca.Function) -> ca.Function:
    """``f`` expanded to SX where that stays small (a loop it holds does not reach its
    outputs), else as it is (or :func:`fused`, where it holds no loop): expanded, a loop's Newton
    solve is unrolled, every iteration and fallback evaluated at every call, into each function
    that reads it (a pump's one loop: a 4 MB C function each, 15x the simulation time of the MX
    call graph)."""
    if expanded_size(f) > EXPAND_TRY_MAX:      # (expanding to find out took minutes on a fluid model)
        return f
    return _kept(f, expanded(f))


def _kept(f: ca.Function, e: ca.Function) -> ca.Function:
    """:func:`compact`'s choice between ``f`` and ``e``, its expansion: ``e`` unless it is SX
    past COMPACT_SX_MAX instructions."""
    return e if not e.is_a("SXFunction") or e.n_instructions() <= COMPACT_SX_MAX else f


def compact_together(*fs: ca.Function | None) -> list:
    """:func:`compact` of each of ``fs`` (None stays None), those that expand small expanded and
    merged together, as :func:`expanded_together` does (one by one, a bottle of gas merged its
    medium's expressions eight times: 12 of its 80 CPU-s compile)."""
    memo: dict = {}
    small = [f is not None and expanded_size(f, memo) <= EXPAND_TRY_MAX for f in fs]
    made = iter(expanded_together(*(f for f, s in zip(fs, small) if s)))
    return [_kept(f, next(made)) if s else f for f, s in zip(fs, small)]


def expanded_size(f: ca.Function, memo: dict | None = None) -> float:
    """About how many SX instructions ``f`` expands to, from its call graph: each call inlines
    its callee (a conditional, each branch), an elementwise operation costs one per entry."""
    memo = {} if memo is None else memo
    key = hash(f)     # the function itself (each which_function() is a new Python wrapper of it)
    if key in memo:
        return memo[key]
    if f.is_a("SXFunction"):
        size = float(f.n_instructions())
    elif f.is_a("MXFunction"):
        size = 0.0
        for k in range(f.n_instructions()):
            size += _node_size(f, k, memo)
            if size > EXPAND_TRY_MAX:
                break
    elif f.class_name() == "FastNewton":       # (SX calls it: not inlined)
        size = 1.0
    elif f.class_name() == "Switch":         # (a short-circuit conditional: every branch inlined)
        size = sum(expanded_size(g, memo) for g in f.find_functions(1) if g.name().startswith("f_"))
    else:       # (another solver or an external: called, not inlined)
        size = 1.0
    memo[key] = size
    return size


#: MX operations that move entries without computing (no SX instruction)
_MOVES = {getattr(ca, f"OP_{op}") for op in ("VERTCAT", "HORZCAT", "DIAGCAT", "VERTSPLIT", "HORZSPLIT",
                                             "DIAGSPLIT", "GETNONZEROS", "GETNONZEROS_PARAM",
                                             "RESHAPE", "SUBREF", "INPUT", "OUTPUT", "CONST",
                                             "PARAMETER", "TRANSPOSE", "PROJECT", "GET_ELEMENTS")
          if hasattr(ca, f"OP_{op}")}


def _node_size(f: ca.Function, k: int, memo: dict) -> float:
    op = f.instruction_id(k)
    if op == ca.OP_CALL:
        return expanded_size(f.instruction_MX(k).which_function(), memo)
    if op in _MOVES:
        return 0
    try:
        return max(1, f.instruction_MX(k).nnz())
    except RuntimeError:        # (no node to ask)
        return 1


def invariants_in(invariants: ca.SX, dae: Dae, x_impl, z_orig):
    """The invariants, written in the semi-explicit unknowns."""
    return ca.substitute(invariants, ca.vertcat(dae.x, dae.z), ca.vertcat(x_impl, z_orig))


def semi_state_names(xs: ca.SX, dae: Dae) -> list[str]:
    """Names of the semi-explicit states (original states, then differentiated variables)."""
    lookup = {str(s): n for s, n in zip(ca.vertsplit(dae.x), dae.x_names)}
    lookup.update({str(s): n for s, n in zip(ca.vertsplit(dae.z), dae.z_names)})
    return [lookup.get(str(s), str(s)) for s in ca.vertsplit(xs)]


def _preferred(dae) -> ca.Function:
    """(x, z, u, p, t, x') -> each variable declared ``stateSelect = prefer`` (or ``always``)
    less its start value: the pins the initial system takes first where its equations leave
    states free."""
    names = [n for n in dae.preferred if n in dae.exprs]
    value = ca.vertcat(*[dae.exprs[n] - dae.preferred[n] for n in names]) if names else ca.SX(0, 1)
    return ca.Function("preferred", [dae.x, dae.z, dae.u, dae.p, dae.t, dae.dx], [value])


def _initial_rows(joint, zfun, zargs, extra=()) -> ca.MX:
    """The initial system's rows (``joint``'s: invariants, initial equations, wishes) in the
    ODE's arguments ``zargs[:3]`` (x, (u, p), t), with the algebraic unknowns they read from
    ``zfun`` inlined: the blocks no row reads are then not in their graph. A robot's 375
    accelerations and forces, solved by QR at run time, kept its whole initial system in MX,
    each Newton step a dense Jacobian through that solve (seconds); its rows read positions
    and velocities alone, and expand to SX. ``extra``: (SX symbol, its MX argument) pairs the
    rows also read."""
    zs, _, rows, xs, up, t = joint
    used = sorted(set(ca.jacobian_sparsity(rows, zs).get_col())) if zs.numel() else []
    Z = zfun.call(zargs, True, False)[0]
    zu = ca.vertcat(*[zs[i] for i in used]) if used else ca.SX(0, 1)
    f = ca.Function("rows", [xs, zu, up, t, *[s for s, _ in extra]], [rows])
    return f(zargs[0], ca.vertcat(*[Z[i] for i in used]) if used else ca.MX(0, 1), zargs[1], zargs[2],
             *[a for _, a in extra])


def _pseudo_transient_rows(dae, joint, invariant_rows, implicit, X, U, P, T, zfun, zargs) -> ca.Function:
    """(x, u, p, t, x_prev, 1/h) -> the initial system's rows (no wishes) with each der() of
    an original state read as its right-hand side less the implicit Euler step's difference
    quotient from x_prev: at 1/h = 0, the initial system itself (see steady.py).
    ``implicit``: the original states, their der() and the algebraic unknowns in joint's."""
    zs, g, _, xs, up, t = joint
    x_impl, dxi, z_orig = implicit
    xp, inv_h = ca.SX.sym("xp", xs.numel()), ca.SX.sym("inv_h")
    quotient = inv_h * (x_impl - ca.substitute(x_impl, xs, xp))
    init = ca.substitute(dae.init_residual, ca.vertcat(dae.x, dae.dx, dae.z),
                         ca.vertcat(x_impl, dxi - quotient, z_orig))
    XP, IH = ca.MX.sym("xp", xs.numel()), ca.MX.sym("inv_h")
    out = _initial_rows((zs, g, ca.vertcat(invariant_rows, init), xs, up, t), zfun, zargs,
                        [(xp, XP), (inv_h, IH)])
    return ca.Function("pseudo", [X, U, P, T, XP, IH], [out])


def _initialiser(dae, xs, X, U, P, T, hard, nh, x_names, joint, pseudo=None):
    """(p -> start values s, (u, p, t, s) -> consistent x0): invariants + initial equations
    (der() of a state is its right-hand side) + chosen start values (s is an argument, so an FMU
    can take a state's start value from its user), those of the variables declared ``stateSelect
    = prefer`` first (wishes: each less its start value). ``hard``: the equations (the first
    ``nh`` rows) and the wishes in (X, U, P, T); ``joint``: (z, g, the same rows, x, (u, p), t)
    in SX, with the algebraic unknowns z not solved for."""
    nx = xs.numel()
    semi_start = ca.Function("sst", [dae.p], [_starts_of(xs, dae)])(P)

    # the system in SX where it expands (its Jacobian is then sparse and cheap: 10 s in MX for
    # 800 R-C sections), else in MX (it holds the Newton solve of an algebraic loop)
    H = ca.Function("H", [X, U, P, T], [hard])
    # (not where the expansion would be huge: a variant of NonCircularPipes with no loop left,
    # its pipes' mass and energy given by pressure and enthalpy, filled 17 GB expanding this,
    # IF97 water's functions inlined at every volume and port)
    H = H if too_large_to_expand(H) else expanded(H)
    sym = ca.SX.sym if H.is_a("SXFunction") else ca.MX.sym
    Xs, Us, Ps, Ts, Ss = (sym(n, k) for n, k in (("x", nx), ("u", U.numel()), ("p", P.numel()),
                                                    ("t", 1), ("s", nx)))
    hard_s = H(Xs, Us, Ps, Ts)
    # numeric Jacobian at the nominal start point, to choose a square nonsingular system
    xs0 = np.array(ca.Function("s0", [P], [semi_start])(dae.p_values)).ravel()
    jac_s = ca.jacobian(hard_s, Xs)
    jac = ca.Function("J", [Xs, Us, Ps, Ts], [jac_s])
    fixed = set(n for n, f in zip(dae.x_names, dae.x_fixed) if f)
    at = lambda x: np.array(jac(x, dae.u_start, dae.p_values, 0.0))     # noqa: E731
    try:
        J = _finite_jacobian(at, xs0, x_names)
    except ModelicaError:
        # states without a start value of their own (index reduction's, a hysteresis branch
        # h = f(H) started at 0 where the law divides by h_F - h_R): taken from the equations
        # that give them explicitly, at the other states' starts
        moved = _relaxed(xs0, H, jac_s, at, fixed, dae, x_names, lambda x: _finite(at, x) is not None)
        if moved is not None:
            semi_start, xs0 = _moved_starts(semi_start, xs0, moved), moved
            J = _finite_jacobian(at, xs0, x_names)
        else:
            J = _joint_jacobian(joint, xs0, dae)
            if J is None:
                raise
    if _idle(J):
        # an equation that moves with no state: the algebraic loops have no solution at the
        # states' starts (a drum's pressure at zero mass); which states the equations determine
        # is read from all the unknowns' start values instead
        Jj = _joint_jacobian(joint, xs0, dae)
        if Jj is not None and _idle(Jj) < _idle(J):
            J = Jj
    order = ([i for i, n in enumerate(x_names) if n in fixed]
             + [i for i, n in enumerate(x_names) if n in dae.x_names and n not in fixed]
             + [i for i, n in enumerate(x_names) if n not in dae.x_names])

    def square(J, equilibrate=False):
        """(start, init_start, the initial state at the model's values or None) solving the
        equations independent at J, the other states pinned to their start values."""
        # each state's column scaled to its largest entry: which rows are independent is then
        # the same whatever the states' units (a pipe's energy in J next to its mass in kg,
        # rows 1e11 against 1e-2, pass for parallel unscaled)
        J = J / np.maximum(np.max(np.abs(J), axis=0, initial=0.0), 1e-300)
        rows = _independent_rows(J[:nh])
        wishes = _granted(J[rows], J[nh:], [i for i in order if x_names[i] in fixed], nx)
        rows += [nh + k for k in wishes]
        J = J[rows]
        # the states the equations determine: a basis of J's columns taken from the end of ``order``
        # (the rest, pinned to their start values, are then the first ``order`` can give: the
        # greedy choice on the dual matroid)
        basis = _column_basis(J, order[::-1])
        if len(basis) < len(rows):
            raise ModelicaError("cannot find a consistent initial state (singular initial system)")
        chosen = set(basis)
        pins = [i for i in order if i not in chosen]
        for i in basis:
            if x_names[i] in fixed:
                log.warning("start value of %s is not used: the state is determined by constraints",
                            x_names[i])
        S = ca.MX.sym("s", nx)
        start = ca.Function("start", [P], [semi_start], ["p"], ["s"])
        empty = ca.SX(0, 1) if sym is ca.SX.sym else ca.MX(0, 1)
        residual = ca.vertcat(hard_s[rows] if rows else empty, Xs[pins] - Ss[pins] if pins else empty)
        A_s = ca.jacobian(residual, Xs)
        if not ca.depends_on(A_s, Xs):
            # linear: one exact solve, no Newton iteration
            Ab = ca.Function("Ab", [Xs, Us, Ps, Ts, Ss], [A_s, residual])
            A, b = Ab(ca.DM.zeros(nx), U, P, T, S)
            x0 = _linear_start(A, b, S) if nx else ca.MX(0, 1)
            init_start = ca.Function("init_start", [U, P, T, S], [x0], ["u", "p", "t", "s"], ["x0"])
            return start, init_start, _nominal(init_start, xs0, dae)
        R = ca.Function("R", [Xs, Us, Ps, Ts, Ss], [residual])
        Q = ca.MX.sym("q", U.numel() + P.numel() + 1 + nx)
        cut = np.cumsum([0, U.numel(), P.numel(), 1, nx]).tolist()
        if equilibrate:
            # the unknowns and rows scaled at the start values (a walk's end, next to a
            # solution whose Jacobian spans 1e-33 to 1e12: unscaled, Newton's steps are lost
            # to rounding and its tolerance is out of reach of the largest rows)
            cols, rows_s = (ca.DM(v) for v in _equilibration(ca.Function("A", [Xs, Us, Ps, Ts, Ss], [A_s]), xs0, dae))
            G = ca.Function("G", [X, Q], [rows_s * R(X / cols, *ca.vertsplit(Q, cut))])
            x0 = _loop_solve("init", G, S * cols, ca.vertcat(U, P, T, S), strict=True) / cols
        else:
            G = ca.Function("G", [X, Q], [R(X, *ca.vertsplit(Q, cut))])
            x0 = _loop_solve("init", G, S, ca.vertcat(U, P, T, S), strict=True)
        init_start = ca.Function("init_start", [U, P, T, S], [x0], ["u", "p", "t", "s"], ["x0"])
        x0 = _nominal(init_start, xs0, dae)
        if x0 is None:
            # no solution from the start values (rotation matrices started at 0 where the joints
            # give them explicitly): the starts the explicit equations give, where those solve
            moved = _relaxed(xs0, H, jac_s, at, fixed, dae, x_names,
                             lambda x: _nominal(init_start, x, dae) is not None)
            if moved is not None:
                start = ca.Function("start", [P], [_moved_starts(semi_start, xs0, moved)], ["p"], ["s"])
                x0 = _nominal(init_start, moved, dae)
        if x0 is None:
            # still none: the states' starts leave an algebraic unknown where its equations have
            # no solution or no derivative (a drum's mass and energy without a start value, its
            # pressure and level from the water's properties): the starts of the states the
            # equations determine taken from a solve in every unknown, from the algebraic
            # unknowns' start values, which the modeller gives
            try:
                together = _joint(joint, rows, pins, S, U, P, T, dae)
            except (ModelicaError, RuntimeError):      # (singular in all the unknowns)
                together = None
            x0 = _nominal(together, xs0, dae) if together is not None else None
            if x0 is not None:
                # (a run starts from the start values it was solved from, not from relaxed
                # ones the solve above did not meet)
                init_start, start = together, ca.Function("start", [P], [semi_start], ["p"], ["s"])
        return start, init_start, x0

    walked, unwalked = False, None

    def walk():
        """square() at the end of a pseudo-transient walk from the start values (see steady.py),
        the starts moved there (``unwalked``: as they were); None where the walk or solve fails."""
        nonlocal semi_start, xs0, walked, unwalked
        walked = True
        if pseudo is None or not nh:
            return None
        moved = _walked(pseudo(), xs0, order, nh, lambda x: _unmet(H, x, dae, nh), dae)
        Jm = _finite(at, moved) if moved is not None else None
        if Jm is None:
            return None
        unwalked = semi_start, xs0
        semi_start, xs0 = _moved_starts(semi_start, xs0, moved), moved
        try:
            other = square(Jm, equilibrate=True)
        except ModelicaError:
            other = None
        if other is None or other[2] is None:
            semi_start, xs0 = unwalked
            return None
        return other

    try:
        start, init_start, x0 = square(J)
    except ModelicaError:
        # singular at the start values (pipes of water at rest, all at one pressure): where
        # the model's dynamics lead
        other = walk()
        if other is None:
            raise
        start, init_start, x0 = other
    if x0 is None:
        # no solve: the equations chosen again where the relaxed starts leave them all finite
        # (the rows and pins chosen at rotation matrices of 0 are not those of a mechanism)
        moved = _relaxed(xs0, H, jac_s, at, fixed, dae, x_names, lambda x: _finite(at, x) is not None)
        if moved is not None:
            kept = semi_start, xs0
            semi_start, xs0 = _moved_starts(semi_start, xs0, moved), moved
            try:
                other = square(_finite(at, moved))
            except ModelicaError:
                other = (None, None, None)
            if other[2] is not None:
                start, init_start, x0 = other
            else:
                semi_start, xs0 = kept
    # equations independent elsewhere may look dependent at the start values (a rotation's
    # invariant at angle 0): where the solve leaves one of them unmet, the equations are
    # chosen again next to the start, and that choice kept if it meets them all better
    worst = _unmet(H, x0, dae, nh)
    if worst > INIT_TOL:
        # next to the start, and at the solution found (where the starts were no place to
        # look: a mechanism's rotations started at 0, EngineV6_analytic)
        near = [_beside(xs0, scale) for scale in (1e-3, 1e-2)]
        for point in near + ([_beside(x0, 1e-3)] if x0 is not None else []):
            Jn = _finite(at, point)
            if Jn is None:
                continue
            try:
                other = square(Jn)
            except ModelicaError:
                continue
            better = _unmet(H, other[2], dae, nh)
            if better <= INIT_TOL or better < 1e-3 * worst:     # (not rounding traded for rounding)
                (start, init_start, _), worst = other, better
            if worst <= INIT_TOL:
                break
    if worst > INIT_TOL and not walked:
        # still unmet (a steady state with the water at rest at the start values)
        other = walk()
        better = _unmet(H, other[2], dae, nh) if other is not None else np.inf
        if better < worst:
            (start, init_start, _), worst = other, better
        elif other is not None:
            semi_start, xs0 = unwalked
    # judged where a run starts: from the start values ``start`` gives
    return start, init_start, _unmet(H, _nominal(init_start, np.array(start(dae.p_values)).ravel(), dae), dae, nh)


def _equilibration(A: ca.Function, x: np.ndarray, dae) -> tuple[np.ndarray, np.ndarray]:
    """(each unknown's column maximum, each row's inverse size) of the Jacobian ``A`` at ``x``:
    the unknowns times the first have columns of at most 1, and the rows times the second are
    relative to the size of their terms (a pressure's mass balance, terms of 1e11, is met to
    rounding at 1e-5; a tank's heat balance needs 1e-12)."""
    J = np.abs(np.nan_to_num(np.array(A(x, dae.u_start, dae.p_values, 0.0, x), float)))
    cols = J.max(axis=0, initial=0.0)
    size = steady.term_sizes(J, x)
    return np.where(cols > 0, cols, 1.0), 1.0 / np.where(size > 0, size, 1.0)


def _walked(pseudo: ca.Function, xs0: np.ndarray, order: list[int], nh: int, unmet, dae):
    """The end of a pseudo-transient walk (steady.py) from the start values ``xs0``: each
    step solves the rows independent at the first step with the other states pinned (those
    the user fixed first, as ``order`` gives), at the model's parameter values."""
    u, p = dae.u_start, dae.p_values
    X, XP, IH = (ca.MX.sym(n, k) for n, k in (("x", xs0.size), ("xp", xs0.size), ("inv_h", 1)))
    r = pseudo(X, u, p, 0.0, XP, IH)
    J = _finite(lambda x: ca.Function("J", [X, XP, IH], [ca.jacobian(r, X)])(x, x, 1.0 / steady.H0), xs0)
    if J is None:
        return None
    J = J / np.maximum(np.max(np.abs(J), axis=0, initial=0.0), 1e-300)
    rows = _independent_rows(J[:nh])
    basis = _column_basis(J[rows], order[::-1])
    if len(basis) < len(rows):
        return None
    pins = [i for i in order if i not in set(basis)]
    s = ca.DM(xs0)
    res = ca.vertcat(r[rows], X[pins] - s[pins]) if pins else r[rows]
    step = ca.Function("step", [X, XP, IH], [res, ca.jacobian(res, X)])
    x = steady.walk(step, unmet, xs0, INIT_TOL)
    if x is not None:
        x[pins] = xs0[pins]
    return x


def _linear_start(A: ca.MX, b: ca.MX, S: ca.MX) -> ca.MX:
    """x0 of A x0 + b = 0, a linear initial system chosen with the discrete values' starts;
    where another mode makes A singular but leaves the equations consistent, the solution
    nearest the start values ``S`` (a geared axis started at rest with its acceleration 0: its
    bearing friction locked makes that equation hold for any controller state, which then
    keeps its start value), else NaN."""
    sol = -_sparse_qr(A, b)
    near = S + _least_squares_step(A, ca.mtimes(A, S) + b)
    rows = 1.0 / (ca.sum2(ca.fabs(A)) + 1e-300)       # (judged row by row in the rows' own scale)
    met = ca.norm_inf(rows * (ca.mtimes(A, near) + b)) <= 1e-8 * (1 + ca.norm_inf(rows * b))
    return ca.if_else(_all_finite(sol), sol, ca.if_else(ca.logic_and(_all_finite(near), met), near, np.nan))


def _joint(joint, rows: list, pins: list, S: ca.MX, U: ca.MX, P: ca.MX, T: ca.MX, dae) -> ca.Function:
    """(u, p, t, s) -> x0 from the initial system's ``rows`` and ``pins`` solved with the
    algebraic equations, every unknown at once, in block-triangular order: with a drum's
    pressure and level pinned, the water's properties follow explicitly and then its mass and
    energy, where solving for the pressure from a mass started at 0 fails. The algebraic
    unknowns' start values, which the modeller gives, are the guesses of its loops."""
    zs, g, hard, xs, up, t = joint
    nx = S.numel()
    s = ca.SX.sym("s", nx)
    w = ca.vertcat(xs, zs)
    empty = ca.SX(0, 1)
    residual = ca.vertcat(g, hard[rows] if rows else empty, xs[pins] - s[pins] if pins else empty)
    guess = np.concatenate([_start_values(xs, dae), _start_values(zs, dae)])
    solve, _, _ = causalise(residual, w, [s, up, t], guess, short=False)
    return ca.Function("init_start", [U, P, T, S], [solve(S, ca.vertcat(U, P), T)[:nx]],
                       ["u", "p", "t", "s"], ["x0"])


def _finite(f, x):
    """``f(x)`` as an array where it is finite, None where it is not or fails (a loop's solve
    inside)."""
    try:
        v = np.array(f(x))
    except RuntimeError:
        return None
    return v if np.all(np.isfinite(v)) else None


def _nominal(init_start, s, dae):
    """The initial state from start values ``s`` at the model's parameter values, None where
    the solve finds none."""
    x0 = _finite(lambda v: init_start(dae.u_start, dae.p_values, 0.0, v), s)
    return None if x0 is None else x0.ravel()


def _granted(J: np.ndarray, wishes: np.ndarray, fixed: list[int], n: int) -> list[int]:
    """The rows of ``wishes`` (pins of preferred variables) kept, in order, each where it is
    independent of the equations ``J``, the pins of the states the user fixed and the wishes
    kept before it (Gram-Schmidt, twice, against an orthonormal basis of those rows; the
    states' columns scaled to their largest entries)."""
    if not len(wishes):
        return []
    base = np.vstack([J, np.eye(n)[fixed]]) if fixed else J
    # (every row of ``base`` counted, as _independent_rows chose them: orth() would drop the
    # numerically weakest one and grant a wish that depends on it)
    Q = np.linalg.qr(base.T)[0] if base.size else np.zeros((n, 0))
    kept = []
    for k, w in enumerate(wishes):
        if Q.shape[1] >= n:
            break
        v = w.astype(float)
        for _ in range(2):
            v = v - Q @ (Q.T @ v)
        # (relative to the row itself, down to a floor: the columns are scaled to their
        # largest entries, and a tank's level, m/(A d), was 7e-9 beside its temperature's
        # U/(m c) at m = 0, and left its start at 0 where an absolute 1e-8 was asked for; a
        # row of 1e-114 there moves no state)
        if np.linalg.norm(v) > 1e-8 * max(np.linalg.norm(w), WISH_FLOOR):
            Q = np.hstack([Q, (v / np.linalg.norm(v))[:, None]])
            kept.append(k)
    return kept


def _unmet(H, x0, dae, nh: int) -> float:
    """The largest residual of the whole initial system (every equation, those left out of the
    square one included, but not the preferred variables' pins: the first ``nh`` rows of H) at
    ``x0``, at the model's parameter values."""
    if x0 is None:
        return np.inf
    try:
        r = np.abs(np.array(H(x0, dae.u_start, dae.p_values, 0.0)).ravel())[:nh]
    except RuntimeError:
        return np.inf
    if not r.size:
        return 0.0
    return float(np.max(r)) if np.all(np.isfinite(r)) else np.inf


def _moved_starts(semi_start, xs0: np.ndarray, moved: np.ndarray):
    """The start values' expressions with those the relaxation moved replaced by its numbers."""
    return ca.vertcat(*[ca.MX(m) if m != s0 else e for e, s0, m in zip(ca.vertsplit(semi_start), xs0, moved)])


def _unit_entries(jac_s, at, start):
    """(row, column, +-1) where the initial system's Jacobian is +-1: read from its
    expression where that is SX, else where two evaluations (at points no model is special
    at) agree on it (an MX one holds loop solves)."""
    if isinstance(jac_s, ca.SX):
        rows, cols = jac_s.sparsity().get_triplet()
        for k, (r, c) in enumerate(zip(rows, cols)):
            coef = jac_s.nz[k]
            if coef.is_constant() and abs(float(coef)) == 1.0:
                yield r, c, float(coef)
        return
    looks = _two_looks(at, start)
    if looks is None:
        return
    unit = np.isclose(np.abs(looks[0]), 1.0, rtol=0, atol=1e-12) & (looks[0] == looks[1])
    for c, r in zip(*np.nonzero(unit.T)):          # state by state, as the SX triplets
        yield r, c, float(looks[0][r, c])


def _beside(x: np.ndarray, scale: float) -> np.ndarray:
    """``x`` moved by ``scale`` of each entry's size (at least 1) in a pattern no model is
    special at (no entry 0, no two alike)."""
    return x + scale * np.sin(1.0 + 2.0 * np.arange(x.size)) * (1.0 + np.abs(x))


def _two_looks(at, start):
    """The Jacobian ``at`` two points beside ``start`` (see :func:`_beside`), None where it
    cannot be evaluated there."""
    try:
        return [at(_beside(start, scale)) for scale in (1e-3, 1e-2)]
    except RuntimeError:
        return None


def _constant_entries(at, start):
    """(row, column, value) where the initial system's Jacobian is the same nonzero number at
    two points no model is special at (a coefficient of the parameters alone)."""
    looks = _two_looks(at, start)
    if looks is None:
        return
    same = np.isfinite(looks[0]) & (looks[0] != 0) & (looks[0] == looks[1])
    for c, r in zip(*np.nonzero(same.T)):
        yield r, c, float(looks[0][r, c])


def _relaxed(start, H, jac_s, at, fixed: set, dae, x_names, ok, sweeps: int = 8):
    """Start values moved by Jacobi sweeps over the initial equations that give a state
    explicitly (coefficient +-1 wherever the equations are looked at; the states the user
    fixed left alone): each such state takes the value its equation gives at the others
    (where that is finite), until ``ok``. Numbers at the model's parameter values; None if
    no sweep helps."""
    pairs, rows_taken, cols_taken = [], set(), set()
    for r, c, coef in _unit_entries(jac_s, at, start):
        if r not in rows_taken and c not in cols_taken and x_names[c] not in fixed:
            pairs.append((r, c, coef))
            rows_taken.add(r)
            cols_taken.add(c)
    if not pairs:
        return None
    r_idx, c_idx, coef = (np.array(v) for v in zip(*pairs))
    # each ``ok`` is a solve of the whole initial system (2 s for a drum boiler's, failing):
    # a sweep that lands where one was tried before has reached its fixed point, and the
    # sweeps after it would too
    seen = [np.array(start, float)]          # (the caller's own try)

    def tried(x) -> bool:
        if any(np.allclose(x, y, rtol=1e-12, atol=0.0, equal_nan=True) for y in seen):
            return True
        seen.append(x.copy())
        return False

    residual = (lambda x: np.array(H(x, dae.u_start, dae.p_values, 0.0)).ravel())     # noqa: E731
    x = np.array(start, float)
    for _ in range(sweeps):
        try:
            res = residual(x)
        except RuntimeError:          # a loop inside cannot be solved there
            return None
        step = res[r_idx] / coef
        finite = np.isfinite(step)
        x = x.copy()
        x[c_idx[finite]] -= step[finite]
        if tried(x):
            break
        if ok(x):
            return x
    # Jacobi sweeps move every state from the others' old values: along a mechanism's chain of
    # frames a wrong (0) orientation travels as far as the right one, and a rod's direction
    # from them stays 0/0 (PlanarLoops_analytic). The states one at a time instead, each after
    # the ones its equation reads (Gauss-Seidel in dependency order): one sweep carries the
    # joints' values down the whole chain
    # (here also a state its row gives with another constant coefficient: a rod's direction,
    # its vector over its length, which Jacobi sweeps leave at 0)
    for r, c, coef in _constant_entries(at, start):
        if r not in rows_taken and c not in cols_taken and x_names[c] not in fixed:
            pairs.append((r, c, coef))
            rows_taken.add(r)
            cols_taken.add(c)
    x = np.array(start, float)
    levels = _in_dependency_order(pairs, jac_s.sparsity())
    for _ in range(sweeps):
        try:
            for level in levels:
                res = residual(x)
                for r, c, k in level:
                    step = res[r] / k
                    if np.isfinite(step):
                        x[c] -= step
        except RuntimeError:
            return None
        if tried(x):
            break
        if ok(x):
            return x
    return None


def _in_dependency_order(pairs: list, sparsity: ca.Sparsity) -> list[list]:
    """``pairs`` (row, column, coefficient: the row gives the column's state) in levels, each
    level's states reading only those of the levels before it: one evaluation of the rows
    serves a whole level (a chain's depth of them a sweep, not one per state). The members of
    a cycle are levels of one each, in order."""
    import networkx as nx

    given_by = {r: c for r, c, _ in pairs}
    graph = nx.DiGraph()
    graph.add_nodes_from(range(len(pairs)))
    at = {c: i for i, (_, c, _) in enumerate(pairs)}
    for r, c in zip(*sparsity.get_triplet()):
        if r in given_by and c in at and c != given_by[r]:
            graph.add_edge(at[c], at[given_by[r]])
    condensed = nx.condensation(graph)
    levels = []
    for generation in nx.topological_generations(condensed):
        members = [sorted(condensed.nodes[scc]["members"]) for scc in generation]
        levels.append([pairs[m[0]] for m in members if len(m) == 1])
        levels += [[pairs[i]] for m in members if len(m) > 1 for i in m]
    return [level for level in levels if level]


def _starts_of(syms: ca.SX, dae: Dae) -> ca.SX:
    """The start values of symbols of ``dae``'s x and z (0 for others: differentiated variables)."""
    start = {}
    for vec, values in ((dae.x, dae.x_start), (dae.z, dae.z_start)):
        start.update(zip((v.element_hash() for v in ca.vertsplit(vec)), ca.vertsplit(values)))
    return ca.vertcat(*[start.get(s.element_hash(), ca.SX(0)) for s in ca.vertsplit(syms)])


def _start_values(syms: ca.SX, dae: Dae) -> np.ndarray:
    """The start values of ``syms`` (:func:`_starts_of`) at the model's parameter values."""
    return np.array(ca.Function("starts", [dae.p], [_starts_of(syms, dae)])(dae.p_values)).ravel()


def _column_basis(J: np.ndarray, order: list[int]) -> list[int]:
    """Columns of J, tried in ``order``, each kept when it is independent of those kept before
    (Gram-Schmidt, twice, against an orthonormal basis of the kept ones)."""
    m = J.shape[0]
    if m == 0:
        return []
    if m == J.shape[1]:        # as many independent equations as states: all are determined
        return list(order)
    tol = np.linalg.norm(J) * max(J.shape) * np.finfo(float).eps * 100
    Q = np.zeros((m, m))
    kept = []
    for i in order:
        v = J[:, i].astype(float)
        q = Q[:, :len(kept)]
        for _ in range(2):
            v = v - q @ (q.T @ v)
        n = np.linalg.norm(v)
        if n > tol:
            Q[:, len(kept)] = v / n
            kept.append(i)
            if len(kept) == m:
                break
    return kept


def _finite_jacobian(jac, x0: np.ndarray, names) -> np.ndarray:
    """The initial system's Jacobian at the start values ``x0`` (it chooses which equations and
    states to solve); at a singularity there (sqrt(x) at x = 0), a clear error naming the states,
    not a solve started where Newton's method cannot move."""
    def at(x):
        try:
            return jac(x)
        except RuntimeError:          # a loop's solve inside fails there: no numbers at all
            return None

    ok = lambda M: M is not None and bool(np.all(np.isfinite(M)))
    J = at(x0)
    if ok(J) and not _idle(J):
        return J
    # which equations determine which states is the same next to the singularity (a tank's
    # T = H/(m*c) at a mass started at 0, where T is NaN, or held at its start value by a
    # singular linear block's fallback so that it moves with no state): read it there
    for scale in (1e-8, 1e-6, 1e-4):
        Jn = at(x0 + scale * (1.0 + np.abs(x0)))
        if ok(Jn) and (not ok(J) or _idle(Jn) < _idle(J)):
            return Jn
    if ok(J):
        return J
    bad = [] if J is None else sorted({names[j] for j in np.flatnonzero(~np.all(np.isfinite(J), axis=0))
                                       if j < len(names)})
    raise ModelicaError("the initial equations have no finite derivative at the start values of "
                        f"{', '.join(bad[:5]) or 'the states'}: start {'them' if len(bad) > 1 else 'it'} "
                        "away from the singularity")


def _idle(J: np.ndarray) -> int:
    """How many equations move with no state (a zero row of the initial system's Jacobian)."""
    return int(np.sum(~np.any(J != 0, axis=1)))


def _joint_jacobian(joint, x0: np.ndarray, dae) -> np.ndarray | None:
    """The initial system's Jacobian in the states, with the algebraic unknowns eliminated
    at their start values (dH/dx - dH/dz (dg/dz)^-1 dg/dx) rather than solved for at the
    states' starts; None where that is not finite."""
    import scipy.sparse
    import scipy.sparse.linalg

    zs, g, hard, xs, up, t = joint
    nx = x0.size
    parts = ca.Function("jj", [xs, zs, up, t], [ca.jacobian(g, xs), ca.jacobian(g, zs),
                                             ca.jacobian(hard, xs), ca.jacobian(hard, zs)])
    z0 = _start_values(zs, dae)
    at = ca.vertcat(dae.u_start, dae.p_values)
    # states started at 0 may make it 0/0 (a vessel's specific energy U/m at no mass): which
    # equations and states are independent is then read with those states at 1; and beside the
    # algebraic start values, where the algebraic equations are singular at them (tried, not yet
    # seen to help: a moist-air room fed straight into a boundary stays singular there)
    ones = np.where(x0 == 0.0, 1.0, x0)
    for x, z in ((x0, z0), (ones, z0), (ones, _beside(z0, 1e-3))):
        gx, gz, hx, hz = (scipy.sparse.csc_matrix(m.sparse()) for m in parts(x, z, at, 0.0))
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", scipy.sparse.linalg.MatrixRankWarning)
                dz = scipy.sparse.linalg.spsolve(gz, gx.toarray()) if zs.numel() else np.zeros((0, nx))
            J = hx.toarray() - hz @ np.asarray(dz).reshape(zs.numel(), nx)
        except (RuntimeError, ValueError):
            continue
        if np.all(np.isfinite(J)):
            return J
    return None


def _independent_rows(J: np.ndarray) -> list[int]:
    """Rows of J that are linearly independent (QR with column pivoting on J^T)."""
    if J.size == 0:
        return []
    _, R, piv = scipy.linalg.qr(J.T, pivoting=True, mode="economic")
    d = np.abs(np.diag(R))
    tol = max(J.shape) * np.finfo(float).eps * (d[0] if d.size else 0) * 100
    return sorted(piv[: int(np.sum(d > tol))].tolist())
