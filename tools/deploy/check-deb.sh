#!/usr/bin/env bash
# Checks omnitrack's Debian packages (tools/deploy/build-deb.sh) without installing them, as CI
# does. Every package: its program, its bash, zsh and fish completions, its manual page and
# copyright are in `dpkg-deb --contents`, and no file is also another package's (dpkg would
# refuse to install both). Then, all of them extracted without root into one scratch directory
# (as if installed together), each program answers --version and --help, and its package holds
# a manual page for every page the program makes and none it does not. The tracker's package
# (omnitrack) also: every file it promises (docs/rig-guide.md, "The Debian package"), /etc's
# files as conffiles, the maintainer scripts, both camera sources in --version, the systemd unit
# through `systemd-analyze verify` (skipped with the reason where systemd-analyze is missing)
# and the sysusers file through `systemd-sysusers --dry-run`. With omnitrack-view beside it,
# `omnitrack run --mcap` finds the view in the installed layout.
#
#   tools/deploy/check-deb.sh target/debian/omnitrack*_0.1.0-1_amd64.deb
set -euo pipefail
[ $# -gt 0 ] || { echo "usage: check-deb.sh PACKAGE.deb..." >&2; exit 2; }
fail() { echo "check-deb.sh: $*" >&2; exit 1; }
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
root="$scratch/root"
mkdir -p "$root"
: > "$scratch/owned"

names=()
for deb in "$@"; do
  name="$(dpkg-deb --field "$deb" Package)" || fail "$deb: not a Debian package"
  names+=("$name")
  # Files only: directories (ending in /) are shared between packages by design.
  dpkg-deb --contents "$deb" | awk '{print $NF}' | grep -v '/$' > "$scratch/$name.files"
  for path in \
    "./usr/bin/$name" \
    "./usr/share/bash-completion/completions/$name" \
    "./usr/share/zsh/vendor-completions/_$name" \
    "./usr/share/fish/vendor_completions.d/$name.fish" \
    "./usr/share/man/man1/$name.1.gz" \
    "./usr/share/doc/$name/copyright"; do
    grep -qxF "$path" "$scratch/$name.files" || fail "$deb: no $path in the package"
  done
  clash="$(sort "$scratch/owned" "$scratch/$name.files" | uniq -d | head -n 3 | tr '\n' ' ')"
  [ -z "$clash" ] || fail "$deb: files another package also holds: $clash"
  cat "$scratch/$name.files" >> "$scratch/owned"
  dpkg-deb -x "$deb" "$root"
  if [ "$name" = omnitrack ]; then
    for path in \
      ./usr/lib/systemd/system/omnitrack.service \
      ./usr/lib/udev/rules.d/99-omnitrack.rules \
      ./usr/lib/tmpfiles.d/omnitrack.conf \
      ./usr/lib/sysusers.d/omnitrack.conf \
      ./etc/default/omnitrack \
      ./etc/omnitrack/tracker.toml \
      ./etc/omnitrack/rig.toml \
      ./usr/share/man/man1/omnitrack-run.1.gz; do
      grep -qxF "$path" "$scratch/$name.files" || fail "$deb: no $path in the package"
    done
    mkdir -p "$scratch/control"
    dpkg-deb --ctrl-tarfile "$deb" | tar -x -C "$scratch/control"
    for conffile in /etc/default/omnitrack /etc/omnitrack/tracker.toml /etc/omnitrack/rig.toml; do
      grep -qxF "$conffile" "$scratch/control/conffiles" || fail "$deb: $conffile is not a conffile"
    done
    for script in postinst prerm postrm; do
      [ -x "$scratch/control/$script" ] || fail "$deb: no executable $script"
    done
    grep -q 'systemd-sysusers omnitrack.conf' "$scratch/control/postinst" || fail "$deb: postinst makes no user"
  fi
done

summary=()
for name in "${names[@]}"; do
  bin="$root/usr/bin/$name"
  version="$("$bin" --version)" || fail "$name --version failed"
  [[ "$version" == "$name "* ]] || fail "$name --version printed: $version"
  "$bin" --help | grep -q "^Usage: $name" || fail "$name --help printed no usage"
  "$bin" manpage --dir "$scratch/pages/$name" 2>/dev/null
  made="$(cd "$scratch/pages/$name" && ls | sed 's/$/.gz/' | sort)"
  shipped="$(sed -n 's|^\./usr/share/man/man1/||p' "$scratch/$name.files" | sort)"
  [ "$made" = "$shipped" ] \
    || fail "$name: manual pages differ from the program's: $(diff <(echo "$made") <(echo "$shipped") | tr '\n' ' ')"
  summary+=("$version ($(grep -c . "$scratch/$name.files") files, $(grep -c . <<<"$made") manual pages)")
done

if [ -x "$root/usr/bin/omnitrack" ]; then
  bin="$root/usr/bin/omnitrack"
  version="$("$bin" --version)"
  for source in v4l usb; do
    grep -q "sources: .*$source" <<<"$version" || fail "the tracker cannot read --source $source: $version"
  done
  if [ -x "$root/usr/bin/omnitrack-view" ]; then
    # `run --mcap` takes the view from beside itself: installed together, it must find it
    # without PATH, and fail on the missing model instead.
    mcap_run="$(env PATH=/nonexistent "$bin" run --model "$scratch/none.obj" --source "replay:$scratch/none" \
      --mcap "$scratch/run.mcap" 2>&1)" && fail "omnitrack run on a missing model succeeded"
    if grep -q 'needs the omnitrack-view program' <<<"$mcap_run" || ! grep -q 'none.obj' <<<"$mcap_run"; then
      fail "omnitrack run --mcap does not find the packaged omnitrack-view: $mcap_run"
    fi
    echo "check-deb.sh: omnitrack run --mcap finds /usr/bin/omnitrack-view beside it"
  fi
  if command -v systemd-analyze >/dev/null 2>&1; then
    # The unit as installed, its ExecStart pointed at the extracted binary (verify requires it to
    # exist); the unit keeps its name.
    mkdir -p "$scratch/unit"
    sed "s|/usr/bin/omnitrack|$bin|g" "$root/usr/lib/systemd/system/omnitrack.service" \
      > "$scratch/unit/omnitrack.service"
    grep -q "^ExecStart=$bin run " "$scratch/unit/omnitrack.service" \
      || fail "the unit does not run the packaged /usr/bin/omnitrack"
    verify="$(systemd-analyze verify "$scratch/unit/omnitrack.service" 2>&1)" || fail "systemd-analyze verify: $verify"
    [ -z "$verify" ] || fail "systemd-analyze verify: $verify"
    echo "check-deb.sh: systemd-analyze verify: the unit is clean"
  else
    echo "check-deb.sh: systemd-analyze verify skipped: systemd-analyze is not installed here"
  fi
  if command -v systemd-sysusers >/dev/null 2>&1; then
    mkdir -p "$scratch/sysroot"
    sysusers="$(systemd-sysusers --root="$scratch/sysroot" --dry-run "$root/usr/lib/sysusers.d/omnitrack.conf" 2>&1)" \
      || fail "systemd-sysusers: $sysusers"
  else
    echo "check-deb.sh: systemd-sysusers --dry-run skipped: systemd-sysusers is not installed here"
  fi
fi
for line in "${summary[@]}"; do
  echo "check-deb.sh: $line: every promised file there"
done
