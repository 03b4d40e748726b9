"""ONERA benchmark: reader, checker, solver and bound on hand-made instances whose optima are found by brute force.

The brute force is independent of the checker: it enumerates every combination of request modes (none, one
observation, one stereo pair, any observation per periodic slot), checks each satellite's activities in
every order with earliest integer starts, and scores with the rules as written in docs/formats.md.
"""

import itertools
import math
import random

import numpy as np
import pytest

from eosp.cli import main
from eosp.onera.model import OneraSchedule, read_onera, read_pb, read_schedule
from eosp.onera.check import best_values, validate
from eosp.kinds.onera.search import GreedyConfig, OneraConfig, solve
from eosp.kinds.onera.bound import lp_bound

STATION = "43.6,1.44,0.0"
TINY = f"""5
0,2,ONE_SHOT_MONO
10,0,100,160,30,10.0,10.0,0.0,0.95
11,1,100,200,30,10.0,10.0,0.0,0.55
1,2,ONE_SHOT_MONO
12,0,110,150,30,11.0,10.0,0.0,0.85
13,1,300,400,20,11.0,10.0,0.0,0.45
2,2,LONG_MONO
14,1,120,200,50,12.0,10.0,0.0,0.75
15,0,140,260,50,12.0,10.0,0.0,0.65
3,4,ONE_SHOT_STEREO
0,16,1,150,220,10,30.0,10.0,0.0,0.95
0,17,1,225,260,10,30.0,10.0,0.0,0.95
1,18,0,500,560,10,30.0,10.0,0.0,0.7
1,19,0,565,600,10,30.0,10.0,0.0,0.7
4,4,PERIODIC
0,20,0,1100,1300,20,40.0,10.0,0.0,0.0
1,21,1,2000,2100,20,40.0,10.0,0.0,0.95
2,22,1,3000,3100,20,40.0,10.0,0.0,0.95
2,23,0,3000,3050,20,40.0,10.0,0.0,0.55
2
900,0,1000,1200,{STATION}
901,1,1000,1400,{STATION}
"""

CLASSES = [(0.5, 0.05), (0.6, 0.1), (0.7, 0.4), (0.8, 0.7), (0.9, 0.95), (1.0, 1.0)]


def cls(score):
    return next(v for b, v in CLASSES if score <= b)


def parse_plain(text):
    """The instance as plain Python lists (a second, naive reading of the format)."""
    lines = text.strip().splitlines()
    n = int(lines[0])
    i, reqs = 1, []
    for _ in range(n):
        rid, nobs, kind = lines[i].split(",")
        i += 1
        obs = []
        for _ in range(int(nobs)):
            p = lines[i].split(",")
            i += 1
            slot = int(p.pop(0)) if kind in ("ONE_SHOT_STEREO", "PERIODIC") else 0
            obs.append(dict(id=int(p[0]), sat=int(p[1]), ws=int(p[2]), we=int(p[3]), d=int(p[4]), lat=float(p[5]),
                            lon=float(p[6]), v=cls(float(p[8])) * (4 if kind == "LONG_MONO" else 1), slot=slot,
                            req=int(rid)))
        reqs.append((int(rid), kind, obs))
    dls = []
    for line in lines[i + 1:]:
        p = line.split(",")
        ws, we = int(p[2]), int(p[3])
        dls.append(dict(id=int(p[0]), sat=int(p[1]), ws=ws, we=we, d=min(180, 0.95 * (we - ws)), lat=float(p[4]),
                        lon=float(p[5]), req=-1 - len(dls)))
    return reqs, dls


def modes(kind, obs):
    """Every admissible content of a request, with its value."""
    out = [((), 0.0)]
    if kind in ("ONE_SHOT_MONO", "LONG_MONO"):
        out += [((o,), o["v"]) for o in obs]
    elif kind == "ONE_SHOT_STEREO":
        pairs = {}
        for o in obs:
            pairs.setdefault(o["slot"], []).append(o)
        out += [(tuple(p), sum(o["v"] for o in p)) for p in pairs.values()]
    else:
        slots = sorted({o["slot"] for o in obs})
        options = [[None] + [o for o in obs if o["slot"] == s] for s in slots]
        for pick in itertools.product(*options):
            chosen = [o for o in pick if o is not None]
            if not chosen:
                continue
            gap, max_gap = 0, 0
            for o in pick:
                if o is None:
                    gap += 1
                else:
                    max_gap, gap = max(max_gap, gap), 0
            out.append((tuple(chosen), sum(o["v"] for o in chosen) + 0.5 * (len(slots) - max_gap)))
    return out


def tau(a, b):
    if a["req"] == b["req"]:
        return 0.0
    return min(math.hypot(a["lat"] - b["lat"], a["lon"] - b["lon"]), 90.0)


def sequence(acts):
    """Starts of `acts` on one satellite in some order (each as early as it can), or None when no order fits."""
    for perm in itertools.permutations(acts):
        starts, t, prev = [], None, None
        for a in perm:
            s = a["ws"] if prev is None else max(a["ws"], t + tau(prev, a))
            if s + a["d"] > a["we"] + 1e-9:
                break
            starts.append(s)
            t, prev = s + a["d"], a
        else:
            return list(zip(perm, starts))
    return None


def brute_force(text):
    reqs, dls = parse_plain(text)
    best, best_plan = -1.0, None
    for combo in itertools.product(*[modes(k, obs) for _, k, obs in reqs]):
        value = sum(v for _, v in combo)
        if value <= best:
            continue
        acts = [o for content, _ in combo for o in content] + dls
        plan = []
        for s in sorted({a["sat"] for a in acts}):
            seq = sequence([a for a in acts if a["sat"] == s])
            if seq is None:
                break
            plan += [(s, a["id"], st) for a, st in seq]
        else:
            best, best_plan = value, plan
    return best, best_plan


def random_instance(seed):
    rng = random.Random(seed)
    lines, n = [], 5
    oid = 100
    for r in range(n):
        kind = rng.choice(["ONE_SHOT_MONO", "LONG_MONO", "ONE_SHOT_STEREO", "PERIODIC"])
        lat, lon = rng.uniform(0, 20), rng.uniform(0, 20)
        obs = []
        if kind == "ONE_SHOT_STEREO":
            for pair in range(rng.randint(1, 2)):
                sat, t = rng.randint(0, 1), rng.randint(0, 600)
                for _ in range(2):
                    obs.append(f"{pair},{oid},{sat},{t},{t + 40},{rng.randint(5, 20)},{lat},{lon},0.0,{rng.random():.3f}")
                    oid, t = oid + 1, t + 45
        else:
            for k in range(rng.randint(1, 3)):
                t = rng.randint(0, 700)
                head = f"{k if kind == 'PERIODIC' else ''}," if kind == "PERIODIC" else ""
                obs.append(f"{head}{oid},{rng.randint(0, 1)},{t},{t + rng.randint(25, 90)},{rng.randint(10, 25)},"
                           f"{lat},{lon},0.0,{rng.random():.3f}")
                oid += 1
        lines.append(f"{r},{len(obs)},{kind}")
        lines += obs
    return f"{n}\n" + "\n".join(lines) + f"\n2\n1,0,300,500,{STATION}\n2,1,650,900,{STATION}\n"


def write(tmp_path, text, name="t.pb"):
    p = tmp_path / name
    p.write_text(text)
    return p


def plan_of(rows):
    a = np.array(rows, dtype=np.float64).reshape(-1, 3)
    return OneraSchedule(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2].copy())


@pytest.mark.parametrize("text", [TINY] + [random_instance(s) for s in range(6)], ids=["tiny"] + [f"r{s}" for s in range(6)])
def test_solver_bound_and_checker_agree_with_brute_force(tmp_path, text):
    f = read_pb(write(tmp_path, text))
    opt, plan = brute_force(text)
    res = validate(f, plan_of(plan))
    assert res.valid, res.first
    assert res.value == pytest.approx(opt)
    sol = solve(f, OneraConfig(time_limit=0.3, bound="lp"))
    check = validate(f, sol.schedule)
    assert check.valid, check.first
    assert check.value == pytest.approx(sol.value)
    assert sol.value == pytest.approx(opt)  # tiny: the search finds the optimum
    assert opt <= sol.bound + 1e-6 and opt <= lp_bound(f) + 1e-6 <= best_values(f).sum() + 1e-6
    greedy = solve(f, GreedyConfig(bound="none"))
    assert validate(f, greedy.schedule).valid and greedy.value <= opt + 1e-9


def test_tiny_values(tmp_path):
    f = read_pb(write(tmp_path, TINY))
    assert f.satellites.tolist() == [0, 1]
    assert f.observations.value.tolist()[:6] == [1.0, 0.1, 0.95, 0.05, 4 * 0.7, 4 * 0.4]
    assert f.downloads.duration.tolist() == [180.0, 180.0]
    # periodic: slots 0, 1, 2 (scores 0, 0.95, max(0.95, 0.55)) -> at most 0.05 + 1 + 1 + 0.5 x 3
    assert best_values(f).tolist() == pytest.approx([1.0, 0.95, 2.8, 2.0, 0.05 + 1 + 1 + 1.5])


def test_periodic_trailing_gap_is_not_counted(tmp_path):
    """Only slot 0 of three served: the authors' max gap counts runs followed by a served slot, so 3 - 0."""
    f = read_pb(write(tmp_path, TINY))
    res = validate(f, plan_of([(0, 20, 1200), (0, 900, 1000), (1, 901, 1000)]))
    assert res.valid and res.value == pytest.approx(0.05 + 0.5 * 3)
    res = validate(f, plan_of([(1, 22, 3000), (0, 900, 1000), (1, 901, 1000)]))  # slot 2 only: leading gap 2
    assert res.valid and res.value == pytest.approx(1.0 + 0.5 * 1)


DL = [(0, 900, 1000), (1, 901, 1000)]


@pytest.mark.parametrize("rows, why", [
    ([(0, 77, 100)], "activity 77 is not an observation or download"),
    ([(0, 10, 100), (0, 10, 100)], "scheduled twice"),
    ([(1, 10, 100)], "belongs to satellite 0, not 1"),
    ([(0, 10, 131)], "outside [100, 130]"),
    ([(0, 10, 100)], "download 901"),
    ([(0, 10, 100), (0, 12, 120)] + DL, "satellite 0: activity 12 starts at 120, before the end of activity 10"),
    ([(0, 10, 100), (1, 11, 150)] + DL, "one-shot request 0 has 2 observations"),
    ([(1, 16, 150)] + DL, "stereo request 3 has observations [16]"),
    ([(1, 16, 150), (0, 18, 500)] + DL, "stereo request 3"),
    ([(1, 22, 3000), (0, 23, 3000)] + DL, "periodic request 4 has two observations in one time slot"),
], ids=["unknown", "twice", "satellite", "window", "download", "transition", "one-shot", "half-pair", "two-pairs",
        "slot"])
def test_checker_names_the_first_violation(tmp_path, rows, why):
    f = read_pb(write(tmp_path, TINY))
    if why == "download 901":
        rows = rows + [(0, 900, 1000)]
    res = validate(f, plan_of(rows))
    assert not res.valid and why in res.first, res.first


def test_transition_counts(tmp_path):
    """11 ends at 130 on (10, 10); 14 at (12, 10) needs 2 s more: 131 is too early, 132 fits."""
    f = read_pb(write(tmp_path, TINY))
    assert "transition 2.000 s" in validate(f, plan_of([(1, 11, 100), (1, 14, 131)] + DL)).first
    assert validate(f, plan_of([(1, 11, 100), (1, 14, 132)] + DL)).valid


def test_cli_round_trip(tmp_path, capsys):
    pb = write(tmp_path, TINY)
    d, s, txt = tmp_path / "fl", tmp_path / "s.parquet", tmp_path / "plan.txt"
    assert main(["import", str(pb), "--out", str(d)]) == 0
    f = read_onera(d)
    assert len(f.observations) == 14 and len(f.downloads) == 2
    assert main(["info", str(d)]) == 0
    assert "conflict-free upper bound: 10.3" in capsys.readouterr().out
    assert main(["solve", str(d), "--solver", "onera", "--time-limit", "0.3", "--out", str(s)]) == 0
    said = capsys.readouterr().out
    opt, _ = brute_force(TINY)
    assert f"value {opt:.4f}" in said and "gap" in said
    assert main(["validate", str(d), str(s)]) == 0
    assert capsys.readouterr().out.startswith("valid: value")
    assert main(["export-schedule", str(d), str(s), "--format", "onera", "--out", str(txt)]) == 0
    lines = txt.read_text().splitlines()
    assert lines[0] == "# eosp: onera-plan" and lines[1] == "satellite activity start end"
    sched, _ = read_schedule(s, f)
    assert len(lines) == 2 + len(sched)
    assert main(["validate", str(d), str(txt)]) == 0
    # a plan broken by hand: named, exit 1
    txt2 = tmp_path / "bad.txt"
    txt2.write_text("\n".join(lines[:2] + [ln for ln in lines[2:] if not ln.split()[1] == "900"]) + "\n")
    capsys.readouterr()
    assert main(["validate", str(d), str(txt2)]) == 1
    assert "download 900" in capsys.readouterr().out
    # outputs are not overwritten without --overwrite
    assert main(["import", str(pb), "--out", str(d)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["import", str(pb), "--out", str(d), "--overwrite"]) == 0


BAD = [
    ("0,2,ONE_SHOT_MONO", "0,2,SOMETHING", 2, "request line does not parse"),
    ("10,0,100,160,30", "10,7,100,160,30", 3, "names satellite 7, which has no download"),
    ("12,0,110,150,30", "12,0,110,130,30", 6, "window [110, 130] is shorter than its duration 30"),
    ("1,19,0,565,600,10,30.0,10.0,0.0,0.7", "2,19,0,565,600,10,30.0,10.0,0.0,0.7", 14, "stereo pair"),
    ("4,4,PERIODIC\n0,20,0,1100,1300,20,40.0,10.0,0.0,0.0\n1,21,1,2000,2100,20,40.0,10.0,0.0,0.95\n"
     "2,22,1,3000,3100,20,40.0,10.0,0.0,0.95\n2,23,0,3000,3050,20,40.0,10.0,0.0,0.55", "4,0,PERIODIC", 16,
     "periodic request 4 without slots"),
    ("12,0,110,150,30,11.0,10.0,0.0,0.85", "12,0,110,150,x,11.0,10.0,0.0,0.85", 6, "duration: 'x' is not an integer"),
]


@pytest.mark.parametrize("old, new, line, why", BAD, ids=["request", "satellite", "window", "pair", "periodic", "field"])
def test_bad_input_is_one_line_with_file_and_line(tmp_path, capsys, old, new, line, why):
    assert old in TINY
    pb = write(tmp_path, TINY.replace(old, new, 1), "bad.pb")
    assert main(["import", str(pb), "--out", str(tmp_path / "fl")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{pb}: line {line}: " in err and why in err, err
    assert not (tmp_path / "fl").exists()
