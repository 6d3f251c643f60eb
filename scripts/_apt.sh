# Sourced by the setup scripts: `apt_install WHO PACKAGE...` installs those of Debian's PACKAGEs that are not
# installed yet (as root, or with passwordless sudo); quick when every one is. WHO names the caller in errors.
apt_install() {
  local who=$1 p sudo_=""
  shift
  local missing=()
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    return 0
  fi
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null 2>&1 || { echo "$who: need root or sudo to apt-get install ${missing[*]}" >&2; return 1; }
    sudo_="sudo -n"
  fi
  $sudo_ env DEBIAN_FRONTEND=noninteractive apt-get update -q
  $sudo_ env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
  echo "$who: installed ${missing[*]}"
}
