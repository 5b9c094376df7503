#!/usr/bin/env bash
# Build the development environment of conveyor_twin for one ROS 2 distro, from nothing, without
# any ROS installed or sourced (ROS 2 comes from the PyPI wheels pinned in
# requirements/<distro>.txt).
#
# Each distro has its own environment, .venv-<distro>; .venv is a symlink to the one the last
# setup built (so .venv/bin/conveyor-twin and .venv/bin/python always name a complete one). The
# environment records the distro and the Python it was made for (.venv-<distro>/.setup/env); one
# made for another distro or Python (or an old .venv directory) is removed and rebuilt whole, never
# partly reused.
#
# Steps, each skipped when a stamp in .venv-<distro>/.setup/ says its inputs did not change:
#   1. check the tools (Python 3.11 or 3.12 with headers, cmake, make, C and C++ compilers);
#   2. create .venv-<distro> and pip-install requirements/<distro>.txt;
#   3. patch the wheels' exported CMake files (build-machine include paths;
#      tools/patch_wheel_cmake.py);
#   4. build msg_defs/ (conveyor_twin_msgs) with cmake + make in build/msg_defs-<distro> and
#      install it into the environment's prefix itself: Python package in site-packages,
#      typesupport libraries in lib/ (on the LD_LIBRARY_PATH that ros-wheels-bootstrapper sets
#      when the venv's python starts), share/ and the ament index in share/; then the same
#      for interfaces/simulation_interfaces/ (simulation_interfaces) in
#      build/simulation_interfaces-<distro>;
#   5. add the prefix to AMENT_PREFIX_PATH of every start of the venv's python (a .pth file; the
#      wheels only set LD_LIBRARY_PATH), so ament_index lookups find conveyor_twin_msgs and
#      conveyor_twin;
#   6. pip install -e . (the conveyor_twin package, console scripts in bin/), plus setup.py's
#      data_files (ament index marker, package.xml, cells) into share/;
#   7. point .venv at this environment;
#   8. compile the numba kernels into the environment's cache (conveyor-twin warm-up), so the
#      first run and the first test start in seconds.
#
# Environment: ROS_DISTRO (jazzy, the default, or kilted), PYTHON (interpreter to create the
# environment with; default python3.11, else python3.12, else python3), CC / CXX (compilers), JOBS
# (parallel make jobs). Works with CI=true and no stdin.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
DISTROS='jazzy kilted'
DISTRO=${ROS_DISTRO:-jazzy}
VENV="$ROOT/.venv-$DISTRO"
LINK="$ROOT/.venv"
STAMPS="$VENV/.setup"
REQUIREMENTS="requirements/$DISTRO.txt"
export PIP_NO_INPUT=1 PIP_DISABLE_PIP_VERSION_CHECK=1
START=$SECONDS

say() { printf 'setup: %s\n' "$*"; }
die() { printf 'setup: error: %s\n' "$*" >&2; exit 1; }
elapsed() { printf '%ss' $((SECONDS - START)); }

# The stamp of a step holds the hash of its inputs; a step runs when they differ.
stamp_ok() { [[ -f "$STAMPS/$1" && "$(cat "$STAMPS/$1")" == "$2" ]]; }
stamp_write() { mkdir -p "$STAMPS" && printf '%s\n' "$2" > "$STAMPS/$1"; }
hash_files() { (cd "$ROOT" && sha256sum "$@" | sha256sum | cut -d' ' -f1); }
hash_tree() {
    (cd "$ROOT" && find "$@" -type f -print0 | LC_ALL=C sort -z | xargs -0 sha256sum \
        | sha256sum | cut -d' ' -f1)
}

# pip prints one warning per package for each local index of this machine's pip.conf that does
# not hold it; they are harmless, so keep them out of the log.
quiet_pip() {
    "$VENV/bin/python" -m pip "$@" < /dev/null 2>&1 \
        | { grep -v "^WARNING: Location '.*' is ignored: it is neither a file nor a directory." \
            || true; }
}

[[ " $DISTROS " == *" $DISTRO "* ]] || die "ROS_DISTRO=$DISTRO is not supported:"`
    `" use ROS_DISTRO=jazzy (the default) or ROS_DISTRO=kilted (see docs/platforms.md)"
[[ -f "$ROOT/$REQUIREMENTS" ]] || die "$REQUIREMENTS is missing"

# 1. Tools -------------------------------------------------------------------------------------
command -v cmake > /dev/null || die 'cmake is missing (needed to build msg_defs/): install cmake'
command -v make > /dev/null || die 'make is missing (needed to build msg_defs/): install make'
cc_found=''
for cc in ${CC:-} cc gcc clang; do command -v "$cc" > /dev/null && { cc_found=$cc; break; }; done
[[ -n "$cc_found" ]] || die 'no C compiler (cc, gcc or clang; or set CC): install gcc'
cxx_found=''
for cxx in ${CXX:-} c++ g++ clang++; do
    command -v "$cxx" > /dev/null && { cxx_found=$cxx; break; }
done
[[ -n "$cxx_found" ]] || die 'no C++ compiler (c++, g++ or clang++; or set CXX): install g++'

if [[ -z "${PYTHON:-}" ]]; then
    PYTHON=python3
    # pyenv's shims exist for every installed version, but run only the active ones: try each.
    for py in python3.11 python3.12; do
        "$py" -c '' < /dev/null > /dev/null 2>&1 && { PYTHON=$py; break; }
    done
fi
# A bare name that does not run may be a pyenv shim of an installed, inactive version: take that
# version's interpreter (the newest installed one of that name).
if [[ "$PYTHON" != */* ]] && ! "$PYTHON" -c '' < /dev/null > /dev/null 2>&1 \
        && command -v pyenv > /dev/null 2>&1; then
    for candidate in $(ls -d "$(pyenv root)"/versions/*/bin/"$PYTHON" 2>/dev/null | sort -rV); do
        if "$candidate" -c '' < /dev/null > /dev/null 2>&1; then
            PYTHON=$candidate
            break
        fi
    done
fi
"$PYTHON" -c '' < /dev/null > /dev/null 2>&1 \
    || die "$PYTHON does not run: install Python 3.11 or 3.12, or set PYTHON to one that runs"
py_version=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
[[ "$py_version" == 3.11 || "$py_version" == 3.12 ]] \
    || die "$PYTHON is Python $py_version, the ROS 2 wheels are built for 3.11 and 3.12:"`
          `" set PYTHON=/path/to/python3.12 (or python3.11)"
python_h=$("$PYTHON" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')/Python.h
[[ -f "$python_h" ]] || die "$python_h is missing: msg_defs/ compiles a Python extension;"`
    `" install the Python $py_version development headers (Debian/Ubuntu: python$py_version-dev)"

# 2. Virtual environment and requirements --------------------------------------------------------
# What the environment is made for: a different distro or Python means a new environment.
env_id="distro=$DISTRO python=$py_version"
if [[ -d "$LINK" && ! -L "$LINK" ]]; then
    say "$LINK is an environment of an older layout (one for all distros): removing it"
    rm -rf "$LINK"
fi
if [[ -d "$VENV" ]]; then
    if ! "$VENV/bin/python" -c '' < /dev/null 2> /dev/null; then
        say "$VENV is broken (its interpreter does not start), recreating it"
        rm -rf "$VENV"
    elif ! stamp_ok env "$env_id"; then
        say "$VENV holds $(cat "$STAMPS/env" 2> /dev/null || echo 'an unknown environment'),"`
            `" not $env_id: recreating it"
        rm -rf "$VENV"
    fi
fi
if [[ ! -d "$VENV" ]]; then
    say "creating $VENV ($env_id) with $("$PYTHON" -c 'import sys; print(sys.executable)')"
    "$PYTHON" -m venv "$VENV" \
        || die "$PYTHON -m venv failed (Debian/Ubuntu: install python$py_version-venv)"
    stamp_write env "$env_id"
fi

req_hash=$(hash_files requirements/common.txt "$REQUIREMENTS")
if stamp_ok requirements "$req_hash"; then
    say 'requirements up to date'
else
    say "installing $REQUIREMENTS into $VENV (a few minutes on a cold pip cache)"
    quiet_pip install -q --progress-bar off -r "$ROOT/$REQUIREMENTS"
    # The wheels' CMake files are rewritten by every install: patch them again.
    "$VENV/bin/python" "$ROOT/tools/patch_wheel_cmake.py" < /dev/null
    stamp_write requirements "$req_hash"
    say "requirements installed ($(elapsed))"
fi

# 3./4. Interface packages ----------------------------------------------------------------------
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])' \
    < /dev/null)
# build_interfaces PACKAGE SOURCE_DIR STAMP: build one rosidl package with cmake + make in
# build/STAMP-<distro> and install it into the venv prefix. Rebuilt when its sources change, and
# when the wheels it links against (requirements) change.
build_interfaces() {
    local pkg=$1 src=$2 stamp=$3
    local build="$ROOT/build/$stamp-$DISTRO" hash
    hash=$(printf '%s %s %s' "$(hash_tree "$src")" "$req_hash" "$VENV" | sha256sum \
        | cut -d' ' -f1)
    if stamp_ok "$stamp" "$hash" && [[ -d "$SITE/$pkg" ]] \
            && [[ -f "$VENV/share/ament_index/resource_index/packages/$pkg" ]]; then
        say "$pkg up to date"
        return
    fi
    say "building $src/ ($pkg) against ROS 2 $DISTRO into $VENV"
    "$VENV/bin/python" "$ROOT/tools/patch_wheel_cmake.py" < /dev/null
    rm -rf "$build"
    mkdir -p "$build"
    local log="$build/build.log"
    local jobs=${JOBS:-$(nproc 2> /dev/null || echo 2)}
    # The wheels are found through the venv prefix; nothing of a system ROS is used. The
    # libraries are built as for a wheel (tools/build_wheel.py reuses this build): within the
    # manylinux_2_28 policy (tools/wheelbuild/glibcxx_compat.cpp), without source paths.
    local compat="$build/libglibcxx_compat.a"
    local prefix_map="-ffile-prefix-map=$build=. -ffile-prefix-map=$ROOT=."
    if ! (
        export AMENT_PREFIX_PATH="$VENV" CMAKE_PREFIX_PATH="$VENV" PATH="$VENV/bin:$PATH"
        unset PYTHONPATH
        "$cxx_found" -fPIC -O2 -c "$ROOT/tools/wheelbuild/glibcxx_compat.cpp" \
            -o "$build/glibcxx_compat.o" && ar rcs "$compat" "$build/glibcxx_compat.o" \
        && cmake -S "$ROOT/$src" -B "$build" \
            -DCMAKE_INSTALL_PREFIX="$VENV" \
            -DCMAKE_BUILD_TYPE=Release \
            -DBUILD_TESTING=OFF \
            -DCMAKE_C_COMPILER="$cc_found" \
            -DCMAKE_CXX_COMPILER="$cxx_found" \
            -DPython3_EXECUTABLE="$VENV/bin/python" \
            -DPython3_FIND_VIRTUALENV=ONLY \
            -DCMAKE_C_FLAGS="$prefix_map" -DCMAKE_CXX_FLAGS="$prefix_map" \
            -DCMAKE_CXX_STANDARD_LIBRARIES="$compat" \
            -DCMAKE_SHARED_LINKER_FLAGS=-Wl,--exclude-libs,libglibcxx_compat.a \
        && make -C "$build" -j"$jobs" install
    ) < /dev/null > "$log" 2>&1; then
        tail -n 40 "$log" >&2
        die "building $src/ failed; full log: $log"
    fi
    # The generated Python package must be where the venv's python imports from.
    [[ -d "$SITE/$pkg" ]] || die "$src/ installed, but not into $SITE/$pkg; see $log"
    stamp_write "$stamp" "$hash"
    say "$pkg installed into $VENV ($(elapsed))"
}
# conveyor_twin_msgs, the twin's own messages.
build_interfaces conveyor_twin_msgs msg_defs msg_defs
# simulation_interfaces, the simulator-agnostic interface the twin also serves (the definitions
# of the release Jazzy and Kilted ship; docs/platforms.md).
build_interfaces simulation_interfaces interfaces/simulation_interfaces simulation_interfaces

# 5. AMENT_PREFIX_PATH --------------------------------------------------------------------------
# ros-wheels-bootstrapper.pth re-executes the interpreter with LD_LIBRARY_PATH; nothing sets
# AMENT_PREFIX_PATH. This .pth puts the venv prefix on it (first, once) at every start.
pth="$SITE/conveyor_twin_ament_prefix.pth"
pth_line='import os, sys; _p = os.environ.get("AMENT_PREFIX_PATH", ""); '`
        `'sys.prefix in _p.split(os.pathsep) or os.environ.__setitem__("AMENT_PREFIX_PATH", '`
        `'os.pathsep.join(filter(None, (sys.prefix, _p))))'
if [[ ! -f "$pth" || "$(cat "$pth")" != "$pth_line" ]]; then
    printf '%s\n' "$pth_line" > "$pth"
    say "added $VENV to AMENT_PREFIX_PATH of the venv's python ($pth)"
fi

# 6. The conveyor_twin package --------------------------------------------------------------------
# Data files (package.xml, ament marker, cell YAML files) are copied at install time, so they
# are part of the hash.
pkg_hash=$(hash_files setup.py setup.cfg package.xml resource/conveyor_twin \
    $(cd "$ROOT" && ls conveyor_twin/cell/*.yaml 2> /dev/null))
if stamp_ok package "$pkg_hash" && [[ -x "$VENV/bin/conveyor-twin" ]]; then
    say 'conveyor_twin (editable) up to date'
else
    say 'installing conveyor_twin (pip install -e .)'
    quiet_pip install -q --progress-bar off --no-deps -e "$ROOT"
    # Editable installs do not install setup.py's data_files (pypa/setuptools#3399): install them
    # (ament index marker, share/conveyor_twin/package.xml, cells) with setup.py's own list.
    rm -rf "$VENV/share/conveyor_twin"
    (cd "$ROOT" && PYTHONWARNINGS=ignore "$VENV/bin/python" setup.py -q install_data \
        --install-dir "$VENV" < /dev/null > /dev/null)
    [[ -f "$VENV/share/ament_index/resource_index/packages/conveyor_twin" ]] \
        || die "the data files of setup.py were not installed into $VENV/share"
    stamp_write package "$pkg_hash"
    say "conveyor_twin installed ($(elapsed))"
fi

# 7. .venv -> this environment --------------------------------------------------------------------
if [[ "$(readlink "$LINK" 2> /dev/null)" != ".venv-$DISTRO" ]]; then
    ln -sfn ".venv-$DISTRO" "$LINK"
    say ".venv now points at .venv-$DISTRO"
fi

# 8. numba kernels --------------------------------------------------------------------------------
# Compiled into $VENV/var/cache/conveyor_twin/numba (conveyor_twin/numba_cache.py); again when the
# package's sources, the cells or the environment changed, or the cache is gone.
kernel_cache="$VENV/var/cache/conveyor_twin/numba"
kernel_files=$(cd "$ROOT" && find conveyor_twin -name '*.py' -o -name '*.yaml' | LC_ALL=C sort)
kernel_hash=$(printf '%s %s %s %s' "$(hash_files $kernel_files)" "$req_hash" "$VENV" \
    "$py_version" | sha256sum | cut -d' ' -f1)
# A kernel source edited and changed back drops the cache (numba_cache.py) with the same hash:
# an empty cache is compiled again. (NUMBA_CACHE_DIR, when set, is where numba caches instead.)
if stamp_ok kernels "$kernel_hash" && [[ -n "${NUMBA_CACHE_DIR:-}" \
        || -n "$(find "$kernel_cache" -name '*.nbi' -print -quit 2> /dev/null)" ]]; then
    say 'numba kernels up to date'
else
    say "compiling the numba kernels into $kernel_cache (about a minute the first time)"
    "$VENV/bin/conveyor-twin" warm-up --quiet < /dev/null \
        || die 'conveyor-twin warm-up failed (above): the simulation kernels do not compile'
    stamp_write kernels "$kernel_hash"
    say "numba kernels ready ($(elapsed))"
fi

say "ready in $(elapsed): ROS 2 $DISTRO, Python $py_version in .venv-$DISTRO (.venv):"`
    `" .venv/bin/conveyor-twin, .venv/bin/python -m pytest"
