# Shared by scripts/up and scripts/test: Debian packages and the project's virtualenv.
# Sourced, not run.

VENV="${VOICECTL_VENV:-$PWD/.venv}"

as_root() {
    if [ "$(id -u)" = 0 ]; then "$@"
    elif command -v sudo >/dev/null 2>&1; then sudo "$@"
    else echo "setup: need root (or sudo) for: $*" >&2; return 1
    fi
}

# install_debian_packages PKG... : apt-get install what is missing, updating lists once.
install_debian_packages() {
    local missing=()
    for pkg in "$@"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" \
            || missing+=("$pkg")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    if ! command -v apt-get >/dev/null 2>&1; then
        echo "setup: not a Debian/Ubuntu system; please install: ${missing[*]}" >&2
        return 1
    fi
    echo "setup: installing Debian packages: ${missing[*]}"
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "${missing[@]}" >/dev/null
}

# make_venv EXTRAS : create the virtualenv and install the project (editable) into it.
# The install is skipped when the venv already holds these extras of this pyproject.toml
# (a stamp in the venv says so): the code is editable, only the dependencies need pip.
make_venv() {
    local extras="$1"
    local stamp="$VENV/.voicectl-installed"
    local want
    want="$(sha256sum <pyproject.toml | cut -d" " -f1) ${extras}"
    if [ -x "$VENV/bin/python" ] && [ -f "$stamp" ] && grep -qxF "$want" "$stamp"; then
        return 0
    fi
    if [ ! -x "$VENV/bin/python" ]; then
        echo "setup: making $VENV and installing voicectl${extras} into it (about a minute, once)"
        python3 -m venv "$VENV"
    else
        echo "setup: installing voicectl${extras} into $VENV (new extras, or pyproject.toml changed)"
    fi
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check --upgrade pip >/dev/null
    "$VENV/bin/python" -m pip install -q --disable-pip-version-check -e ".${extras}"
    echo "$want" >>"$stamp"
}
