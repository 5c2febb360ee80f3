#!/usr/bin/env bash
# Rebuild every pretrained model shipped in src/scpformer/pretrained/ from seeds, with the
# project's own commands: generate, split, train, then package (weights-only copy, model card,
# SHA-256 in manifest.json). Each model's card lists the commands below that made it.
#
#   scripts/build_pretrained.sh                       # all four models
#   WORK=../pt scripts/build_pretrained.sh tscvx      # one model (art-rendezvous,
#                                                     # art-robust, tscvx, tscvx-midflight)
#
# Time on the 2-core development machine, from the logs of the shipped models: rendezvous
# data 23 min + ART 21 min (idle machine); made while other jobs ran beside them:
# robust data 60 min + ART 26 min; 6-DoF data: the first 4736 instances of a --n 6000 run stored after 1 h 32 min
# of generation with other jobs beside it, then 7 min of augmentation with two workers
# + T-SCvx networks 20.6 min (the two side by side, one thread each); mid-flight 6-DoF data
# 19 min (one worker, another job beside it) + networks (see tscvx-midflight's card). The whole script has
# not been timed end to end, nor on an idle machine, where it should be shorter. Each
# model builds alone (`scripts/build_pretrained.sh tscvx`); a smaller N_PDG shortens the
# longest stage but makes another T-SCvx model than the shipped one. A rerun resumes the
# dataset generation (`generate` keeps finished shards).
#
# Run from the repository's root. Environment (defaults in brackets): WORK [build/pretrained]
# datasets and runs, OUT [src/scpformer/pretrained] where the packaged models go, WORKERS [2], N_PDG [4736] 6-DoF
# base instances (x8 by the rotation augmentation).
set -euo pipefail

WORK=${WORK:-build/pretrained}
OUT=${OUT:-src/scpformer/pretrained}
WORKERS=${WORKERS:-2}
N_PDG=${N_PDG:-4736}
MODELS=("$@")
[ ${#MODELS[@]} -eq 0 ] && MODELS=(art-rendezvous art-robust tscvx tscvx-midflight)
mkdir -p "$WORK"
cd "$WORK"
OUT=$(cd "$OLDPWD" && mkdir -p "$OUT" && cd "$OUT" && pwd)

# run NAME CMD...: echo CMD, record it in NAME.commands (the model card's recipe), run it
run() {
    local name=$1
    shift
    echo "+ $*" >&2
    echo "$*" >>"$name.commands"
    "$@"
}

art_rendezvous() {
    : >art-rendezvous.commands
    run art-rendezvous scpformer generate rendezvous --n 27000 --seed 0 --out rdv27000 --workers "$WORKERS"
    run art-rendezvous scpformer dataset split rdv27000 --fractions 0.8 0.1 0.1 --seed 0
    run art-rendezvous scpformer train art --data rdv27000 --out art-small27k --preset small --frame rtn --epochs 3 --batch-size 32 --lr 0.001 --seed 0
    python -m scpformer.pretrained.package art-rendezvous art-small27k --commands art-rendezvous.commands --out "$OUT"
}

art_robust() {
    : >art-robust.commands
    run art-robust scpformer generate robust-rendezvous --mode chance --n 4800 --seed 0 --out rob4800 --workers "$WORKERS"
    run art-robust scpformer dataset split rob4800 --fractions 0.8 0.1 0.1 --seed 0
    run art-robust scpformer train art --data rob4800 --out art-robust-roe-small --preset small --frame roe --epochs 8 --batch-size 32 --lr 0.001 --seed 0
    python -m scpformer.pretrained.package art-robust art-robust-roe-small --commands art-robust.commands --out "$OUT"
}

tscvx() {
    : >tscvx.commands
    run tscvx scpformer generate pdg6dof --n "$N_PDG" --seed 4 --out pdg --workers "$WORKERS"
    run tscvx scpformer dataset augment pdg --out pdg8 --workers "$WORKERS"
    run tscvx scpformer dataset split pdg8 --fractions 0.8 0.1 0.1 --seed 0
    run tscvx scpformer train tscvx --data pdg8 --out tscvx-small --preset small \
        --networks tight --threads 1 --report-split test &
    local tight=$!  # the two networks train side by side, one thread each
    run tscvx scpformer train tscvx --data pdg8 --out tscvx-small --preset small \
        --networks solution --threads 1 --report-split test
    wait "$tight"
    python -m scpformer.pretrained.package tscvx tscvx-small --commands tscvx.commands --out "$OUT"
}

# T-SCvx for the closed loop's re-plans: states at nodes 5-35 of optimal descents, with the
# planning margins of the loop (pdg6dof_mpc.planning_instance) as the dataset's bounds
tscvx_midflight() {
    : >tscvx-midflight.commands
    printf '[const]\nt-min = 0.6\nt-max = 4.7\ndelta-max-deg = 18.0\n' >planning.toml
    echo "printf '[const]\\nt-min = 0.6\\nt-max = 4.7\\ndelta-max-deg = 18.0\\n' > planning.toml" >>tscvx-midflight.commands
    run tscvx-midflight scpformer generate pdg6dof --n 1024 --seed 11 --midflight-nodes 5 35 \
        --config planning.toml --out pdgmid --workers "$WORKERS"
    run tscvx-midflight scpformer dataset augment pdgmid --out pdgmid8 --workers "$WORKERS"
    run tscvx-midflight scpformer dataset split pdgmid8 --fractions 0.8 0.1 0.1 --seed 0
    run tscvx-midflight scpformer train tscvx --data pdgmid8 --out tscvx-mid --preset small \
        --networks tight --threads 1 --report-split test &
    local tight=$!
    run tscvx-midflight scpformer train tscvx --data pdgmid8 --out tscvx-mid --preset small \
        --networks solution --threads 1 --report-split test
    wait "$tight"
    python -m scpformer.pretrained.package tscvx-midflight tscvx-mid --commands tscvx-midflight.commands --out "$OUT"
}

for model in "${MODELS[@]}"; do
    case $model in
        art-rendezvous) art_rendezvous ;;
        art-robust) art_robust ;;
        tscvx) tscvx ;;
        tscvx-midflight) tscvx_midflight ;;
        *) echo "build_pretrained.sh: unknown model '$model' (art-rendezvous, art-robust, tscvx, tscvx-midflight)" >&2; exit 2 ;;
    esac
done
echo "packaged ${MODELS[*]} into $OUT; check them with: python -m pytest tests/pretrained"
