"""Where a fleet's first schedule runs its batteries dry, and what the energy windows' accounting misses there.

The first schedule of the fleet solver (construction and coordinate descent, before any battery repair) is
simulated with the checker's battery model (:mod:`eosp.fleet.battery`).  For every satellite whose battery fails,
the stretch from its last full charge (or the horizon start) to the failure is split into what it spent (imaging,
slewing over the maneuver windows, of which the settling seconds, idle) and what it charged, beside the sunlight
the energy windows count for it (:func:`eosp.fleet.energy.sunlit_seconds`, an over-estimate); then the slew
energy of the satellite's whole timeline, split into the first maneuver of each pass (after a gap of more than
10 minutes) and the maneuvers between observations of one pass.

    python experiments/battery_stretches.py CASE_OR_FLEET_DIR
"""

from __future__ import annotations

import argparse
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fleet", help="an aeossp case directory or a fleet directory")
    args = ap.parse_args(argv)

    from eosp.budget import UNLIMITED
    from eosp.fleet.battery import active, levels, segments, simulate
    from eosp.fleet.energy import sunlit_seconds
    from eosp.fleet.timeline import intervals
    from eosp.jobs.train_prices import read_problem
    from eosp.kinds.fleet.config import FleetConfig
    from eosp.kinds.fleet.coordinator import Coordinator
    from eosp.kinds.fleet.construct import construct, descend

    prob = read_problem(args.fleet)
    fleet, sun = prob.fleet, prob.sun
    b, att = fleet.satellites.battery, fleet.satellites.attitude
    coord = Coordinator(prob, FleetConfig(rounds=1, time_limit=None))
    first = coord.empty()
    construct(coord, np.argsort(prob.pass_time[:, 0], kind="stable"), primal=first, whole=True)
    descend(coord, first, list(range(len(prob.passes))), UNLIMITED)
    print(f"first schedule before the repair: WCR {first.value / prob.total_weight:.4f}")
    for sat, tl in enumerate(coord.timelines(first)):
        if not tl.start:
            continue
        obs, man = intervals(prob.los, tl, sat)
        run = simulate(fleet, sun, sat, obs, man)
        if run.ok:
            continue
        seg = segments(fleet, sun, sat, obs, man)
        end, lev = levels(fleet, sun, sat, obs, man)
        kf = int(np.searchsorted(seg.mid, run.fail_us))
        full = np.flatnonzero(lev[:kf] >= float(b.capacity_wh[sat]) - 1e-9)
        k0 = int(full[-1]) + 1 if len(full) else 0
        a_us = int(end[k0 - 1]) if k0 else 0
        d, mid = seg.dur[k0:kf + 1], seg.mid[k0:kf + 1]
        in_obs, in_man = active(obs, mid) >= 0, active(man, mid) >= 0
        n_obs = len(np.unique(active(obs, mid)[in_obs]))
        wh = lambda watts, seconds: float(watts) * float(seconds) / 3600.0  # noqa: E731
        S, step = sunlit_seconds(sun, sat)
        g0, g1 = int(np.floor(a_us / 1e6 / step)), min(len(S) - 1, int(np.ceil(end[kf] / 1e6 / step)))
        start_wh = float(lev[k0 - 1]) if k0 else float(b.initial_wh[sat])
        print(f"satellite {fleet.satellites.ids[sat]}: dry at {end[kf] / 6e7:.0f} min after a stretch of "
              f"{(end[kf] - a_us) / 6e7:.0f} min from {start_wh:.0f} Wh (capacity {float(b.capacity_wh[sat]):.0f}); "
              f"{n_obs} observations; imaging {wh(b.imaging_w[sat], d[in_obs].sum()):.1f} Wh, slewing "
              f"{wh(b.slew_w[sat], d[in_man].sum()):.1f} "
              f"(settling {wh(b.slew_w[sat], att.settling_s[sat] * n_obs):.1f}), "
              f"idle {wh(b.idle_w[sat], d.sum()):.1f}; charged {float((seg.charge[k0:kf + 1] * d).sum()) / 3600:.1f} "
              f"(the windows count {wh(b.sunlit_w[sat], S[g1] - S[g0]):.1f})")
        slew_s = (obs.start - man.start) / 1e6 - float(att.settling_s[sat])
        st, en = np.asarray(tl.start), np.asarray(tl.end)
        opens = np.r_[True, st[1:] - en[:-1] > 600.0]
        print(f"    whole timeline: slew energy of the first maneuver of {int(opens.sum())} passes "
              f"{wh(b.slew_w[sat], slew_s[opens].sum()):.1f} Wh, of the {int((~opens).sum())} maneuvers within passes "
              f"{wh(b.slew_w[sat], slew_s[~opens].sum()):.1f} Wh")
    return 0


if __name__ == "__main__":
    sys.exit(main())
