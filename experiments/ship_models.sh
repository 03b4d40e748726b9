#!/bin/bash
# The exact commands that trained the shipped models (after `python experiments/expert_guided.py data`,
# which builds data/expert/ and its demos).  Runs the two trainings back to back.
cd "$(dirname "$0")/.."
mkdir -p logs
set -e
.venv/bin/python jobs/build_demos.py --data data/expert/train data/expert/val --modes unitary --time-limit 30 --beam 1
.venv/bin/python jobs/pretrain.py --imitation.train-data data/expert/train --imitation.val-data data/expert/val --env.reward unitary --env.max-acquisitions 320 --imitation.epochs 200 --imitation.time-budget 1500 --imitation.dagger-every 2 --imitation.dagger-instances 32 --imitation.dagger-beam 1 --imitation.run-name ship-unitary-v1 --imitation.experiment expert-guided > logs/ship-unitary-v1.log 2>&1
.venv/bin/python jobs/build_demos.py --data data/expert/train data/expert/val --modes utility --action-sets true --beam 1 --sets-max-acquisitions 150 --time-limit 30 > logs/expert_demos_utility_q.log 2>&1
.venv/bin/python jobs/pretrain.py --imitation.train-data data/expert/train --imitation.val-data data/expert/val --env.reward normalized --env.max-acquisitions 320 --imitation.epochs 200 --imitation.time-budget 1500 --imitation.dagger-every 2 --imitation.dagger-instances 48 --imitation.regret-coeff 100 --imitation.set-tolerance 1e-6 --imitation.run-name ship-utility-v2 --imitation.experiment expert-guided > logs/ship-utility-v2.log 2>&1
