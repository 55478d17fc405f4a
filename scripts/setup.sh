#!/usr/bin/env bash
# Set up everything rendiff's external backends need on Debian bookworm, idempotently.
#
#   scripts/setup.sh            # as root (CI), or as a user with passwordless sudo
#
# 1. apt: povray, libembree-dev, libosmesa6, chromium (the report's browser test),
#    mesa-vulkan-drivers + libvulkan1 (lavapipe, software Vulkan, for rendiff-wgpu)
#    (+ libllvm19 when the archive has it, for
#    Mitsuba's optional llvm variant; + python3-venv when venv cannot bootstrap pip).
#    `apt-get update` runs only when something is missing.
# 2. .venv in the repo root with harness/requirements.txt, then PyOpenGL==3.1.10 and
#    pytest, then the harness itself (pip install -e harness). PyOpenGL is installed
#    *after* pyrender on purpose: pyrender pins 3.1.0, which breaks OSMesa; pip's
#    "dependency conflict" message about it is expected.
#    pip is skipped when .venv/.rendiff-stamp matches the hash of those inputs.
#
# Quick (a few seconds) when everything is present. Safe to run repeatedly.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$REPO/.venv"
REQS="$REPO/harness/requirements.txt"
STAMP="$VENV/.rendiff-stamp"
EXTRA_PINS=(PyOpenGL==3.1.10 pytest==8.4.2)
APT_PACKAGES=(povray libembree-dev libosmesa6 chromium mesa-vulkan-drivers libvulkan1)
OPTIONAL_APT=(libllvm19) # Mitsuba llvm_ad_rgb only; scalar_rgb works without it

STEP="start"
HINT=""
on_error() {
    local rc=$?
    echo "" >&2
    echo "setup.sh: FAILED (exit $rc) during: $STEP" >&2
    [[ -n "$HINT" ]] && echo "setup.sh: try: $HINT" >&2
    exit "$rc"
}
trap on_error ERR

step() { STEP="$1"; HINT="${2:-}"; echo "==> $1"; }
note() { echo "    $*"; }

# ---------------------------------------------------------------- privileges
SUDO=()
CAN_APT=1
if [[ $EUID -ne 0 ]]; then
    if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
        SUDO=(sudo -n)
    else
        CAN_APT=0
    fi
fi

is_installed() { dpkg-query -W -f='${Status}' "$1" 2>/dev/null | grep -q "install ok installed"; }
has_candidate() {
    local cand
    cand="$(apt-cache policy "$1" 2>/dev/null | awk '/Candidate:/ {print $2}')"
    [[ -n "$cand" && "$cand" != "(none)" ]]
}

# ---------------------------------------------------------------- 1. system packages
step "checking system packages"
command -v dpkg-query >/dev/null || { echo "setup.sh: dpkg-query not found: this script expects Debian bookworm" >&2; exit 1; }
missing=()
for p in "${APT_PACKAGES[@]}"; do is_installed "$p" || missing+=("$p"); done
if ! command -v python3 >/dev/null 2>&1; then
    missing+=(python3 python3-venv)
elif ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1 && [[ ! -x "$VENV/bin/python" ]]; then
    missing+=(python3-venv) # Debian splits ensurepip out of python3
fi
lists_empty() { ! compgen -G "/var/lib/apt/lists/*_Packages*" >/dev/null; }
optional_missing=()
for p in "${OPTIONAL_APT[@]}"; do
    is_installed "$p" && continue
    # An optional package the archive lacks must not cost an `apt-get update` on every run:
    # only ask apt again when its package lists are empty (fresh container).
    if has_candidate "$p" || lists_empty; then
        optional_missing+=("$p")
    else
        note "skipping $p: not in the configured apt sources (only Mitsuba's optional llvm variant needs it)"
    fi
done

MANUAL_APT=()
if ((${#missing[@]} + ${#optional_missing[@]} > 0)); then
    if ((CAN_APT == 0)); then
        MANUAL_APT=("${missing[@]}" "${optional_missing[@]}")
        note "not root and no passwordless sudo: cannot install ${MANUAL_APT[*]}"
    else
        step "apt-get update (missing: ${missing[*]} ${optional_missing[*]})" \
            "check network access to the Debian mirrors and /etc/apt/sources.list*, then re-run"
        "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
        to_install=("${missing[@]}")
        for p in "${optional_missing[@]}"; do
            if has_candidate "$p"; then
                to_install+=("$p")
            else
                note "skipping $p: not in the configured apt sources (only Mitsuba's optional llvm variant needs it)"
            fi
        done
        if ((${#to_install[@]} > 0)); then
            step "apt-get install ${to_install[*]}" \
                "run 'apt-get install ${to_install[*]}' by hand to see the full error (held packages? disk full?)"
            "${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive \
                apt-get install -y -qq --no-install-recommends "${to_install[@]}" >/dev/null
        fi
    fi
else
    note "all present: ${APT_PACKAGES[*]}"
fi

# ---------------------------------------------------------------- 2. Python venv
if [[ ! -x "$VENV/bin/python" ]] || ! "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1; then
    step "creating $VENV" "install python3-venv (apt-get install python3-venv), or delete a broken .venv and re-run"
    command -v python3 >/dev/null || { echo "setup.sh: python3 missing; install python3 python3-venv" >&2; exit 1; }
    rm -rf "$VENV"
    python3 -m venv "$VENV"
    rm -f "$STAMP"
fi

step "checking Python packages"
[[ -f "$REQS" ]] || { echo "setup.sh: $REQS not found (run from a complete checkout)" >&2; exit 1; }
want="$({ cat "$REQS" "$REPO/harness/pyproject.toml"; printf '%s\n' "${EXTRA_PINS[@]}"; "$VENV/bin/python" -V; } | sha256sum | cut -d' ' -f1)"
have="$(cat "$STAMP" 2>/dev/null || true)"
if [[ "$want" == "$have" ]]; then
    note "up to date (stamp matches $REQS + ${EXTRA_PINS[*]})"
else
    step "pip install -r harness/requirements.txt" \
        "check access to pypi.org; then '$VENV/bin/pip install -r $REQS' to see the full error"
    "$VENV/bin/python" -m pip install --disable-pip-version-check --progress-bar off -q -r "$REQS"
    step "pip install ${EXTRA_PINS[*]} (after pyrender on purpose; the PyOpenGL conflict notice is expected)" \
        "'$VENV/bin/pip install ${EXTRA_PINS[*]}'"
    pip_log="$(mktemp)"
    if ! "$VENV/bin/python" -m pip install --disable-pip-version-check --progress-bar off -q "${EXTRA_PINS[@]}" \
        >"$pip_log" 2>&1; then
        cat "$pip_log" >&2
        rm -f "$pip_log"
        false # -> on_error with this step's hint
    fi
    # pip reports the pyrender/PyOpenGL pin conflict as "ERROR:" but exits 0; hide only that notice.
    grep -v -e "dependency resolver does not currently" -e "dependency conflicts" -e "requires PyOpenGL==3.1.0" \
        "$pip_log" || true
    rm -f "$pip_log"
    # The harness itself, as a package of the venv (editable: the checkout's code), so that
    # `.venv/bin/python -m rendiff_harness` works from any folder.
    step "pip install -e harness (rendiff's Python package)" "'$VENV/bin/pip install --no-deps -e $REPO/harness'"
    "$VENV/bin/python" -m pip install --disable-pip-version-check --progress-bar off -q --no-deps -e "$REPO/harness"
    echo "$want" >"$STAMP"
fi

step "smoke test: import numpy, OpenImageIO" "delete $STAMP and re-run to reinstall the Python packages"
"$VENV/bin/python" -c 'import numpy, OpenImageIO' >/dev/null
(cd / && "$VENV/bin/python" -c 'import rendiff_harness') ||
    { echo "setup.sh: rendiff_harness is not installed in $VENV; delete $STAMP and re-run" >&2; exit 1; }
# The harness's bytecode, written now: an editable install compiles none, and where
# PYTHONDONTWRITEBYTECODE is set (as on rendiff's CI machines) every harness process of a
# check (a dozen workers, the comparison's) compiled the modules it imports from source
# again (42 of 68 modules had none: about 1 s of CPU a main job). Stale files are harmless:
# Python compiles a changed module in memory.
step "compile the harness's bytecode" "'$VENV/bin/python -m compileall -q $REPO/harness/rendiff_harness'"
"$VENV/bin/python" -m compileall -q "$REPO/harness/rendiff_harness" >/dev/null

# ---------------------------------------------------------------- summary
if ((${#MANUAL_APT[@]} > 0)); then
    echo "" >&2
    echo "setup.sh: Python side is ready, but these Debian packages are missing and need root:" >&2
    echo "    apt-get install --no-install-recommends ${MANUAL_APT[*]}" >&2
    echo "  (run that as root, or re-run this script with sudo; libllvm19 is optional)" >&2
    exit 1
fi
echo "setup.sh: OK (venv: $VENV; run tests: cd harness && ../.venv/bin/python -m pytest -q tests)"
