#!/usr/bin/env bash
# Pack Warp (and the few wheels the GPU host lacks) into parts that fit beside this tree in one device call.
#
#   bash benchmarks/pack_for_device.sh            # writes .gpu0/ … .gpuN/ and .gpuw/install.sh (git-ignored)
#
# A device call carries the working tree and its `carry` paths, 64 MiB in all. Warp's wheel is ~150 MB;
# without its examples and tests, as an xz tarball, it is ~100 MB, so with a ~45 MB tree it goes in parts of
# (64 MiB − tree) each. Each call copies its part to ~/gw there; the last one unpacks Warp into ~/site and
# installs the small wheels. On the twentieth session's lease the six calls took 50 s of held time in all
# (the whole-wheel route took ~270 s). Then, in every later call on the same warm machine:
#   export PYTHONPATH=~/site:$PWD WARP_CACHE_PATH=~/wcache PYTHONUNBUFFERED=1
set -euo pipefail
cd "$(dirname "$0")/.."
grep -qx '/.gpu\*/' .git/info/exclude 2>/dev/null || echo '/.gpu*/' >> .git/info/exclude
rm -rf .gpu .gpu[0-9] && mkdir -p .gpu .gpuw
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
  -d .gpu "warp-lang==1.19.0" flip-evaluator OpenEXR trimesh
tmp=$(mktemp -d)
(cd "$tmp" && python3 -m zipfile -e "$OLDPWD"/.gpu/warp_lang-*.whl . && rm -rf warp/examples warp/tests && tar cf - . | xz -6 -T0) > .gpu/warp.tar.xz
rm -rf "$tmp"
tree=$(git ls-files -z | xargs -0 du -cb | tail -1 | cut -f1)
part=$(( 64 * 1024 * 1024 - tree - 4 * 1024 * 1024 ))  # 4 MiB to spare for untracked files and the small wheels
split -b "$part" -d -a 1 .gpu/warp.tar.xz .gpu/part
n=0
for p in .gpu/part[0-9]; do mkdir -p ".gpu$n" && mv "$p" ".gpu$n/part" && n=$((n + 1)); done
last=$((n - 1))
cp .gpu/flip*.whl .gpu/openexr*.whl .gpu/trimesh*.whl ".gpu$last/"
cat > .gpuw/install.sh <<SH
# source .gpuw/install.sh K   (call K of 0 … $last carries .gpuw and .gpuK; the last unpacks and installs)
mkdir -p ~/gw ~/site && cp .gpu\$1/part ~/gw/p\$1
if [ "\$1" = $last ]; then
  cat \$(seq -f "\$HOME/gw/p%g" 0 $last) | xz -d -T8 | tar x -C ~/site
  python3 -m pip install -q --no-index --no-deps --target ~/site .gpu$last/*.whl
fi
export PYTHONPATH=~/site:\$PWD WARP_CACHE_PATH=~/wcache PYTHONUNBUFFERED=1
SH
echo "$n calls: each 'source .gpuw/install.sh K' with carry [\".gpuw\", \".gpuK\"], K = 0 … $last"
