#!/usr/bin/env bash
# Prints one line per scenario and method: a digest of the plan file `vic plan` writes, with the
# solve time and the resolved scenario removed, so that two builds can be compared to the last bit:
#   scripts/plan_digest.sh target/release/vic > a.txt   (on each build)   diff a.txt b.txt
# The light VSA's SOOC plan (minutes) is left out unless FULL=1.
set -euo pipefail
vic=${1:-target/release/vic}
cd "$(dirname "$0")/.."
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for cfg in config/*.toml; do
    stem=$(basename "$cfg" .toml)
    for method in ilqg sooc; do
        if [[ $method == sooc && $stem == two_link_vsa_light_divergent && ${FULL:-0} != 1 ]]; then
            continue
        fi
        if ! "$vic" plan --config "$cfg" --method "$method" --out "$tmp/p.json" >/dev/null 2>"$tmp/err"; then
            echo "$stem $method refused: $(head -c 200 "$tmp/err" | tr '\n' ' ')"
            continue
        fi
        digest=$(python3 -c '
import hashlib, json, sys
d = json.load(open(sys.argv[1]))
d["summary"].pop("solve_ms", None)
d.pop("config", None)  # the resolved scenario: its schema may change while the numbers do not
print(hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:16])' "$tmp/p.json")
        echo "$stem $method $digest"
    done
done
