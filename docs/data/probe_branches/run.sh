set -e
cd /work/main
P=runs/probe_branches
for bp in nearest fixed; do
  .venv/bin/python scripts/collect_demos.py --env-id WindowInstallation-v1 --episodes 300 --seed 200000 --out $P/$bp.npz --resume --branch-preference $bp
  [ -f $P/bc_$bp/checkpoint.pt ] || .venv/bin/python -m baselines.ppo.bc --demos $P/$bp.npz --out $P/bc_$bp/checkpoint.pt --env-id WindowInstallation-v1
  .venv/bin/python scripts/evaluate.py --checkpoint $P/bc_$bp/checkpoint.pt --env-id WindowInstallation-v1 --episodes 200 --seed 500000 --json docs/data/probe_branches/window_clone_$bp.json
done
echo PROBE_DONE
