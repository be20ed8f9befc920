"""The robot scenario of the SLR paper, played on an embedded store (``slr demo``).

Robot X looks at table1 while its components publish, with delays, into SLR:

* the *state publisher*: ``tf(cam, base, pose(..))^T`` (the head pans from left to right)
  and ``tf(base, world, pose(..))^T`` (the base drives along the world x axis);
* *segmentation*: ``seg(O, [X,Y,Z])^T``, object segments relative to the camera;
* *objRec*: ``obj(O, Type, Color)^T``, the type and color of each new segment.

A last scene shows event rules (the event-processing library paper): the paper's relFace rule
detecting a reliable face as (late) face recognitions arrive, and a ``cnot`` rule that waits
until no late event can contradict it.

The *control* component then asks the paper's questions: which cups are on table1 and where
they are in the world, the color of an object, whether a location is fresh, outdated or never
observed, and which objects can be used for tea.  Everything runs through the public API
(``slr_sql.open``, ``kb.load``, ``kb.add_many``, ``kb.query``, ``kb.explain``) so the demo
doubles as a worked example of it.

The demo prints answers exactly like ``slr query`` does: with :func:`value_text` and
:func:`answer_text` of :mod:`slr_sql.answers`, which this module still offers.
"""
from __future__ import annotations

import concurrent.futures
import math
from dataclasses import dataclass, field
from typing import Any, Iterable

import slr_sql

from .answers import answer_text, value_text
from .store import quote_identifier
from .api import KnowledgeBaseAPI
from .kb import KnowledgeBase

__all__ = [
    "ROBOT_PROGRAM", "EVENT_RULES", "TABLE_SWEEP", "DemoQuery", "DemoResult", "scenario_events",
    "open_robot_kb", "demo_queries", "run_demo", "value_text", "answer_text",
]

# --------------------------------------------------------------------------------------------
# The scenario
# --------------------------------------------------------------------------------------------

#: The program of the paper (sections "Persistence and Maintaining State" and "Aggregation"),
#: written in slr_sql syntax: ``next(.., [T, inf])`` for the paper's ``prev(.., [T, ∞])``.
ROBOT_PROGRAM = r"""
% ---- declarations --------------------------------------------------------------------
:- event seg/2.
:- event obj/3.
:- event tf/3.
% The state publisher is a single producer that sends in time order, so `next` over tf can
% answer as soon as the first tf event at or after T has arrived.
:- in_order(tf/3).
:- max_delay(tf/3, 50ms).
% Segmentation and object recognition take a variable time; rather than trusting a delay
% bound, their components say when they are done: fullyUpdated(seg/2)^T, fullyUpdated(obj/3)^T.
:- max_delay(seg/2, 10s).
:- max_delay(obj/3, 10s).
tBuffer(tf(_S, _D, _TF), 300s).

% ---- persistent knowledge: the color is the last observed one ------------------------
color(O, C)^T :- prev(obj(O, _, C)^_Z, T).

% ---- persistence with temporal validity ----------------------------------------------
location(O, L)^T :- prev(seg(O, L)^Z, T), T - Z =< 5, !.
location(O, "outdated")^T :- prev(seg(O, _)^Z, T), T - Z > 5, !.
location(_, "never-observed")^_.

% ---- continuous knowledge: camera->base by interpolation -----------------------------
tf(cam, base, TF)^T :-
    prev(tf(cam, base, TF1)^T1, T),
    next(tf(cam, base, TF2)^T2, [T, inf]),
    interpolate([TF, T], [TF1, T1], [TF2, T2]).

% ---- base->world: interpolate if the next observation is within 1 s, else hold -------
tf(base, world, TF)^T :-
    prev(tf(base, world, TF1)^T1, T),
    (   next(tf(base, world, TF2)^T2, [T, T+1])
    ->  interpolate([TF, T], [TF1, T1], [TF2, T2])
    ;   extrapolate([TF, T], [TF1, T1])
    ).

% ---- an object's position in the world frame -----------------------------------------
position(seg(O, RelPos)^T, WorldPos) :-
    tf(cam, base, TF1)^T,
    tf(base, world, TF2)^T,
    pos_multiply([RelPos, TF1, TF2], WorldPos).

% ---- static knowledge -----------------------------------------------------------------
usedFor(cup, tea).
usedFor(cup, coffee).
usedFor(mug, coffee).
usedFor(glass, water).

% table1's top, as a box in the world frame: [XMin, XMax], [YMin, YMax], [ZMin, ZMax].
surface(table1, [1.5, 2.5], [-0.5, 0.5], [0.6, 1.0]).
on(Surface, [X, Y, Z]) :-
    surface(Surface, [X0, X1], [Y0, Y1], [Z0, Z1]),
    X0 =< X, X =< X1, Y0 =< Y, Y =< Y1, Z0 =< Z, Z =< Z1.
"""

#: The control component's look at table1: the head sweeps it from t1 to t2.
TABLE_SWEEP = (10.0, 14.0)


def _yaw_pose(xyz: list[float], yaw_degrees: float) -> Any:
    """``pose([X,Y,Z],[QX,QY,QZ,QW])`` for a rotation of ``yaw_degrees`` about z."""
    half = math.radians(yaw_degrees) / 2.0
    return slr_sql.Struct("pose", (list(xyz), [0.0, 0.0, math.sin(half), math.cos(half)]))


@dataclass(frozen=True)
class Publication:
    """One event as a component publishes it: ``arrival`` is when it reaches the store."""

    component: str
    name: str
    args: tuple
    time: float
    arrival: float

    def as_tuple(self) -> tuple:
        return (self.name, list(self.args), self.time, self.time)


def scenario_events() -> list[Publication]:
    """Every event of the scenario, in arrival order.

    The head pans from +20° (t=10) to -20° (t=14) in steps of 10°/s; the camera sits 0.1 m
    ahead of and 1.2 m above the base.  The base drives along world x at 0.2 m/s from x=1.0
    (t=10) to x=1.4 (t=12), stops publishing for a while, and is seen again at x=1.7 (t=15).
    Segmentation reports each segment 0.3 s after its image; objRec 0.8 s after.

    >>> pubs = scenario_events(); len(pubs)
    20
    >>> [(p.component, p.name, p.args[0], p.time, p.arrival) for p in pubs if p.args[0] == "cup1"]
    [('segmentation', 'seg', 'cup1', 10.5, 10.8), ('objRec', 'obj', 'cup1', 10.5, 11.3)]
    """
    pubs: list[Publication] = []
    for i, t in enumerate([10.0, 11.0, 12.0, 13.0, 14.0, 15.0]):
        pubs.append(Publication("statePublisher", "tf",
                                ("cam", "base", _yaw_pose([0.1, 0.0, 1.2], 20.0 - 10.0 * i)),
                                t, t + 0.01))
    for t, x in [(10.0, 1.0), (11.0, 1.2), (12.0, 1.4), (15.0, 1.7)]:
        pubs.append(Publication("statePublisher", "tf",
                                ("base", "world", _yaw_pose([x, 0.0, 0.0], 0.0)), t, t + 0.01))
    sightings = [  # (time, object, position relative to the camera, type, color)
        (10.5, "cup1", [0.8, 0.1, -0.4], "cup", "red"),
        (11.5, "cup2", [0.9, -0.2, -0.4], "cup", "blue"),
        (12.5, "book1", [0.7, 0.0, -0.35], "book", "green"),
        (13.5, "cup3", [2.0, -0.3, -0.4], "cup", "white"),   # a cup on the next table
        (13.6, "mug1", [0.75, -0.1, -0.38], "mug", "yellow"),
    ]
    for t, o, rel, typ, color in sightings:
        pubs.append(Publication("segmentation", "seg", (o, rel), t, t + 0.3))
        pubs.append(Publication("objRec", "obj", (o, typ, color), t, t + 0.8))
    pubs.sort(key=lambda p: (p.arrival, p.time))
    return pubs


def open_robot_kb(db_path: str | None = None, clock: Any = None):
    """Open a store with the robot program loaded; returns ``(kb, clock)``.

    >>> kb, clock = open_robot_kb(); clock.now()
    0.0
    >>> kb.query("usedFor(cup, U)")
    [{'U': Atom('tea')}, {'U': Atom('coffee')}]
    >>> kb.close()
    """
    clock = clock if clock is not None else slr_sql.ManualClock(0.0)
    kb = slr_sql.open(db_path, clock=clock)
    kb.load(ROBOT_PROGRAM)
    return kb, clock


def publish(kb: KnowledgeBaseAPI, clock: Any, pubs: Iterable[Publication]) -> None:
    """Deliver publications in arrival order, moving the manual clock to each arrival.

    >>> kb, clock = open_robot_kb(); publish(kb, clock, scenario_events())
    >>> clock.now(), kb.query("color(cup2, C)^20")
    (15.01, [{'C': Atom('blue')}])
    >>> kb.close()
    """
    for pub in pubs:
        if pub.arrival > clock.now():
            clock.set(pub.arrival)
        kb.add_event(pub.name, list(pub.args), start=pub.time, end=pub.time)


@dataclass(frozen=True)
class DemoQuery:
    """A question of the control component: ``goal`` asked over the stream view ``at``."""

    title: str
    goal: str
    at: float | None
    why: str


@dataclass
class DemoResult:
    query: DemoQuery
    answers: list[dict[str, Any]]
    plan: str = ""
    notes: list[str] = field(default_factory=list)


CUPS_ON_TABLE1 = DemoQuery(
    "Which cups did you see on table1, and where are they in the world?",
    "findall(O-WorldPos, (obj(O, cup, _)^_, next(seg(O, RelPos)^T, [%g, %g]), "
    "position(seg(O, RelPos)^T, WorldPos), on(table1, WorldPos)), Cups)" % TABLE_SWEEP,
    TABLE_SWEEP[1],
    "cups recognised by objRec, segmented during the sweep, placed in the world via "
    "tf cam->base (interpolated) and base->world (interpolated or held), kept if on table1",
)


def demo_queries() -> list[DemoQuery]:
    """The demo's questions after the synchronized one: each a goal, its time and why it answers
    so.

    >>> q = demo_queries()[1]; q.title, q.goal
    ('What color is cup2?', 'color(cup2, C)^20')
    >>> kb, clock = open_robot_kb(); publish(kb, clock, scenario_events())
    >>> kb.query(q.goal, at=q.at)
    [{'C': Atom('blue')}]
    >>> kb.close()
    """
    t2 = TABLE_SWEEP[1]
    return [
        CUPS_ON_TABLE1,
        DemoQuery("What color is cup2?", "color(cup2, C)^20", None,
                  "persistence: the color of the last obj(cup2, _, C) at or before 20"),
        DemoQuery("Where is cup1 (camera frame) at t=13?", "location(cup1, L)^13", None,
                  "temporal validity: the last segment of cup1 is 2.5 s old, so it is fresh"),
        DemoQuery("Where is cup1 at t=20?", "location(cup1, L)^20", None,
                  "the last segment of cup1 is 9.5 s old (> 5 s): the second rule says outdated"),
        DemoQuery("Where is plate9 at t=13?", "location(plate9, L)^13", None,
                  "no segment of plate9 at all: the first two rules fail, the third one answers"),
        DemoQuery("Where is the base in the world at t=13.5?", "tf(base, world, TF)^13.5", None,
                  "no base->world observation within [13.5, 14.5]: the last one is held (extrapolate)"),
        DemoQuery("Which objects can be used for tea, and where are they?",
                  "findall(object(O, WPos), (obj(O, Type, _)^_, usedFor(Type, tea), "
                  "prev(seg(O, RPos)^T2, %g), position(seg(O, RPos)^T2, WPos)), List)" % t2,
                  t2,
                  "the paper's aggregation query: every cup seen up to t=14, at its last segment"),
    ]


def _plan_line(kb: KnowledgeBaseAPI, goal: str) -> str:
    try:
        plan = kb.explain(goal)
    except Exception as exc:  # the plan is commentary: never let it stop the demo
        return f"(no plan: {exc})"
    # The first line repeats the goal; the next one says which engine runs it.
    lines = [line.strip() for line in str(plan).splitlines() if line.strip()]
    informative = [line for line in lines if not line.startswith("goal:")]
    return (informative or lines or [""])[0]


def _print_result(console: Any, result: DemoResult) -> None:
    from rich.markup import escape   # goals, plans and notes are text: a list [a, b] in
                                     # them is no markup tag

    q = result.query
    at = "" if q.at is None else f"   [dim](at={q.at:g})[/dim]"
    console.print(f"\n[bold cyan]control>[/bold cyan] [bold]{escape(q.title)}[/bold]")
    console.print(f"  [green]?-[/green] {escape(q.goal)}.{at}", markup=True, highlight=False)
    if not result.answers:
        console.print("  [red]false.[/red]")
    for answer in result.answers:
        for line in _display_answer(answer):
            console.print("  " + line, markup=False, highlight=False)
    console.print(f"  [dim]why: {escape(q.why)}[/dim]", highlight=False)
    if result.plan:
        console.print(f"  [dim]plan: {escape(result.plan)}[/dim]", highlight=False)
    for note in result.notes:
        console.print(f"  [yellow]{escape(note)}[/yellow]", highlight=False)


def _display_answer(answer: dict[str, Any]) -> list[str]:
    """An answer for people: floats to 3 decimals, and a list of several items one per line."""
    if not answer:
        return ["true."]
    from .terms import Struct, Var

    lines = []
    for name, value in answer.items():

        if isinstance(value, Var):
            continue  # a findall's template variables: unbound, and noise here
        if isinstance(value, list) and len(value) > 1 and any(
                isinstance(item, (list, Struct)) for item in value):
            lines.append(f"{name} = [")
            lines.extend(f"    {value_text(item, 3)}," for item in value[:-1])
            lines.append(f"    {value_text(value[-1], 3)}")
            lines.append("  ]")
        else:
            lines.append(f"{name} = {value_text(value, 3)}")
    return lines


def _synchronized_cups_query(kb: KnowledgeBase, clock: Any, console: Any) -> DemoResult:
    """The cups question asked *before* segmentation and objRec have finished the sweep.

    The control component submits ⟨cups, t2⟩ as soon as the head stops at t2; the query
    waits until seg/2 and obj/3 are complete up to t2 (their components send
    ``fullyUpdated(..)^t2``) and tf/3 is complete (its max_delay has passed).
    """
    pubs = scenario_events()
    t2 = TABLE_SWEEP[1]
    before = [p for p in pubs if p.arrival <= t2]
    after = [p for p in pubs if p.arrival > t2]
    publish(kb, clock, before)
    notes = []

    def answered() -> str:
        # Answers are produced by the store's scheduler: let it finish reacting, then say
        # whether the query is answered or what it still waits for.
        sync = kb.synchronizer
        if sync is not None:
            sync.drain(timeout=5.0)
        elif isinstance(pending, concurrent.futures.Future):  # a local query's is one
            concurrent.futures.wait([pending], timeout=0.3)
        if pending.done():
            return "answered yet: True"
        waits = getattr(pending, "waiting_for", None) or []
        return ("waiting for " + ", ".join(
            f"{w.type} up to {w.time:g}" for w in sorted(waits, key=lambda w: w.type))
            + "; " if waits else "") + "answered yet: False"

    pending = kb.submit(CUPS_ON_TABLE1.goal, at=t2, id="cups-on-table1")
    notes.append(f"t={clock.now():g}: submitted at={t2:g}: {answered()}")
    publish(kb, clock, after)
    notes.append(f"t={clock.now():g}: all segments, recognitions and tf arrived: {answered()}")
    for component, type_ in (("segmentation", "seg/2"), ("objRec", "obj/3")):
        kb.add(f"fullyUpdated({type_})^{t2:g}")
        notes.append(f"t={clock.now():g}: {component} sent fullyUpdated({type_})^{t2:g}: "
                     f"{answered()}")
    answers = pending.result(timeout=5.0)
    waited = ""
    if hasattr(pending, "explain"):
        waited = "".join("\n       " + line for line in pending.explain().splitlines())
    q = DemoQuery("(synchronized) " + CUPS_ON_TABLE1.title, CUPS_ON_TABLE1.goal, t2,
                  "a synchronized query waits until every event type it depends on is "
                  "complete up to its time: here until both perception components said so"
                  + waited)
    return DemoResult(q, answers, notes=notes)


#: The event-rule scene (the event-processing library paper): a reliable face, and a door
#: the robot left open -- a negation that must wait until no late door_closed can come.
EVENT_RULES = r"""
relFace(F) <- (face(F, R1) seq face(F, R2) seq face(F, R3)) within 5
              where (R1 > 60, R2 > R1, R3 > R2).
:- max_delay(door_closed/1, 2s).
:- max_delay(door_open/1, 2s).
:- max_delay(robot_left/1, 2s).
doorLeftOpen(D) <- (door_open(D) seq robot_left(_R)) cnot door_closed(D).
"""


def _event_rules_scene(console: Any, db_path: str | None = None) -> list[DemoResult]:
    """Event rules: complex events detected as the events arrive (one of them late), with
    the events that made each one, and a cnot rule that waits. In the demo's file when it
    has one (``slr demo --db``; the types are the scene's own), else in memory."""
    clock = slr_sql.ManualClock(0.0)
    results = []
    with slr_sql.open(db_path, clock=clock) as kb:
        kb.load(EVENT_RULES, "event_rules.slr", name="event_rules")
        console.rule("[bold]event rules (the event-processing library paper)[/bold]")
        for line in EVENT_RULES.strip().splitlines():
            console.print(f"  [dim]{line}[/dim]", markup=True, highlight=False)
        # the face recognizer's results, one of them late (arrival order != occurrence)
        faces = [("face(antonio, 65)^8", 8.3), ("face(antonio, 90)^11", 11.3),
                 ("face(antonio, 70)^9", 11.5), ("face(bob, 61)^1", 1.3),
                 ("face(bob, 59)^2", 2.3), ("face(bob, 70)^3", 3.3)]
        notes = []
        for text, arrival in sorted(faces, key=lambda f: f[1]):
            clock.set(max(clock.now(), arrival))
            kb.add(text)
        notes.append("face(antonio, 70)^9 arrived last (t=11.5), after the face at 11: "
                     "matching is by occurrence time, so it still completes 8 -> 9 -> 11; "
                     "bob's 61, 59, 70 do not rise")
        info = kb.event_rules()[0]
        why = kb.store.rule_matches(quote_identifier(info["provenance"]), 3)
        for r1, r2, r3, start, end in why:
            notes.append(f"relFace over [{start:g}, {end:g}] is made of the face rows "
                         f"{r1}, {r2}, {r3} ({info['provenance']})")
        q = DemoQuery("Which faces were recognized reliably?",
                      "findall(F-[S, E], relFace(F)^[S, E], L)", None,
                      "relFace(F) is a complex event: stored in its own table, detected in "
                      "the transaction of the add that completed it")
        results.append(DemoResult(q, kb.query(q.goal), plan="event rule, compiled to SQL",
                                  notes=notes))
        _print_result(console, results[-1])

        notes = []
        for text, arrival in [("door_open(d1)^20", 20.1), ("robot_left(r1)^25", 25.1)]:
            clock.set(arrival)
            kb.add(text)
        pending = kb.event_rules()[1]["pending"]
        notes.append(f"t={clock.now():g}: door d1 open at 20, robot left at 25: "
                     f"{pending} candidate waiting -- a door_closed(d1) inside [20, 25] "
                     f"could still arrive until door_closed/1 is complete up to 25 "
                     f"(max_delay 2 s: after t=27)")
        clock.set(26.0)
        kb.add("door_closed(d1)^22")
        notes.append("t=26: a late door_closed(d1)^22 arrives, inside [20, 25]")
        clock.set(27.5)
        notes.append(f"t=27.5: door_closed/1 complete up to 25: decided, no complex event "
                     f"(the door was closed); pending: {kb.event_rules()[1]['pending']}")
        for text, arrival in [("door_open(d2)^30", 30.1), ("robot_left(r1)^33", 33.1)]:
            clock.set(arrival)
            kb.add(text)
        clock.set(35.5)
        notes.append("t=35.5: door d2 open at 30, robot left at 33, no door_closed(d2) by "
                     "t=35 (complete up to 33): doorLeftOpen(d2) detected, arrival 35.5")
        q = DemoQuery("Which doors did the robot leave open?",
                      "findall(D-[S, E], doorLeftOpen(D)^[S, E], L)", None,
                      "cnot: no door_closed(D) strictly inside the interval, decided only once "
                      "door_closed/1 is complete up to its end, so a late event is never missed")
        results.append(DemoResult(q, kb.query(q.goal), plan="event rule with cnot: waits for "
                                  "completeness in slr_cep_pending", notes=notes))
        _print_result(console, results[-1])
    return results


def run_demo(console: Any = None, db_path: str | None = None) -> list[DemoResult]:
    """Play the scenario and print every question with its answers; returns the results.

    It takes half a second: the example asks one of its questions as it asks them, over the
    published scenario (``slr demo`` prints them all).

    >>> kb, clock = open_robot_kb(); publish(kb, clock, scenario_events())
    >>> question = demo_queries()[2]; question.title
    'Where is cup1 (camera frame) at t=13?'
    >>> kb.query(question.goal, at=question.at)
    [{'L': [0.8, 0.1, -0.4]}]
    >>> kb.close()
    """
    if console is None:
        from rich.console import Console

        console = Console()
    kb, clock = open_robot_kb(db_path)
    results: list[DemoResult] = []
    try:
        console.rule("[bold]SLR demo: robot X looks at table1[/bold]")
        console.print("[dim]program: color persistence, location validity with cut, tf interpolation "
                      "and extrapolation, position in the world frame, usedFor/2[/dim]")
        if hasattr(kb, "submit"):
            results.append(_synchronized_cups_query(kb, clock, console))
            _print_result(console, results[-1])
        else:
            publish(kb, clock, scenario_events())
        counts: dict[str, int] = {}
        for pub in scenario_events():
            counts[pub.component] = counts.get(pub.component, 0) + 1
        console.print("[dim]published: " + ", ".join(f"{c} {n} events" for c, n in counts.items())
                      + f"; clock now {clock.now():g}[/dim]")
        for query in demo_queries():
            answers = kb.query(query.goal, at=query.at)
            result = DemoResult(query, answers, plan=_plan_line(kb, query.goal))
            results.append(result)
            _print_result(console, result)
    finally:
        kb.close()
    results += _event_rules_scene(console, db_path)
    return results
