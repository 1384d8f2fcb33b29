"""Strong, strong cyclic and weak plans as fixpoints over a game (docs/semantics.md §8, *Plans*).

With ``T`` the target, ``A(m)`` the admissible commands at ``m`` (those whose
every result lies in Safe, and whose skill inputs the goal gives) plus
waiting when an outcome is enabled, and ``Post(m, a)`` every marking move
``a`` may lead to::

    CPre(X)      = { m in Safe : exists a in A(m), Post(m, a) <= X }
    CPre_c(Z, X) = { m in Z & Safe : exists a in A(m), Post(m, a) <= Z and Post(m, a) & X != {} }
    W   = mu X. T | CPre(X)                  strong: reached whatever the outcomes
    W_c = nu Z. mu X. T | CPre_c(Z, X)       strong cyclic (Cimatti, Pistore, Roveri and Traverso,
                                             "Weak, strong, and strong cyclic planning via symbolic
                                             model checking", AIJ 147, 2003)
    E   = mu X. T | { m in Safe : exists a in A(m), Post(m, a) & X != {} }   weak (a way exists)

Each least fixpoint keeps its iterates, ``layers[k]`` = the markings from which
the goal is reached within ``k`` moves (worst case for W, when outcomes are
favourable for W_c): a marking's *rank* is the first layer holding it, and the
policy descends from layer ``k`` to ``k - 1`` ("descent in basin", as omega's
``games/gr1.py`` builds its strategies).  ``Z`` starts at ``Safe | T`` rather
than at every marking: a move with ``Post(m, a) <= Z`` is then admissible by
construction, as in ``CPre``, where ``X <= Safe | T``.

The solvers are the same loops over two representations of the sets
(:class:`Game`): boolean arrays over the explored graph
(:mod:`skinet.plan.explicit`) and BDDs over the product
(:mod:`skinet.plan.symbolic`).  Cost: at most ``d + 1`` steps per least
fixpoint (``d``: the number of layers), times at most ``|W_c|`` outer steps for
W_c (a handful in practice); each step costs one pass over the game.  The
deadline is checked before every step; past it the answer is ``None`` (the
caller answers ``unknown``, never ``none``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, Protocol, TypeVar

S = TypeVar("S")


class Game(Protocol, Generic[S]):
    """The sets and pre-images one solver works with (markings, plus DONE for a ``run`` goal)."""

    target: S
    safe: S

    def strong_pre(self, x: S) -> S: ...
    def cyclic_pre(self, z: S, x: S) -> S: ...
    def weak_pre(self, x: S) -> S: ...
    def same(self, a: S, b: S) -> bool: ...


Expired = Callable[[], bool]


def strong(game: Game[S], expired: Expired) -> list[S] | None:
    """The layers of ``W = mu X. T | CPre(X)``; None when ``expired`` first."""
    return _attractor(game, game.strong_pre, expired)


def weak(game: Game[S], expired: Expired) -> list[S] | None:
    """The layers of ``E``, the markings from which some safe way reaches the goal."""
    return _attractor(game, game.weak_pre, expired)


def cyclic(game: Game[S], expired: Expired) -> list[S] | None:
    """The layers of the last ``mu X`` of ``W_c = nu Z. mu X. T | CPre_c(Z, X)``; None when ``expired`` first."""
    z = game.safe | game.target
    zold = None
    layers: list[S] | None = None
    while zold is None or not game.same(z, zold):
        zold = z
        layers = _attractor(game, lambda x, z=z: game.cyclic_pre(z, x), expired)
        if layers is None:
            return None
        z = layers[-1]
    return layers


def _attractor(game: Game[S], pre: Callable[[S], S], expired: Expired) -> list[S] | None:
    """``mu X. T | pre(X)`` with its iterates."""
    layers = [game.target]
    while True:
        if expired():
            return None
        x = layers[-1] | pre(layers[-1])
        if game.same(x, layers[-1]):
            return layers
        layers.append(x)
