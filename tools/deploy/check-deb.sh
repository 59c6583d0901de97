#!/usr/bin/env bash
# Checks a Debian package of omnitrack (tools/deploy/build-deb.sh) without installing it, as CI
# does: every file the package promises (docs/rig-guide.md, "The Debian package") is in
# `dpkg-deb --contents`, /etc's files are conffiles and the maintainer scripts are there; then,
# extracted without root into a scratch directory, the binary answers --version (with the
# v4l and usb sources) and --help, the package holds a manual page for every page the binary
# makes and none it does not, the systemd unit passes `systemd-analyze verify` (skipped with the
# reason where systemd-analyze is missing) and the sysusers file `systemd-sysusers --dry-run`.
#
#   tools/deploy/check-deb.sh target/debian/omnitrack_0.1.0-1_amd64.deb
set -euo pipefail
deb="${1:?usage: check-deb.sh PACKAGE.deb}"
fail() { echo "check-deb.sh: $deb: $*" >&2; exit 1; }
scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT

contents="$(dpkg-deb --contents "$deb" | awk '{print $NF}')"
for path in \
  ./usr/bin/omnitrack \
  ./usr/lib/systemd/system/omnitrack.service \
  ./usr/lib/udev/rules.d/99-omnitrack.rules \
  ./usr/lib/tmpfiles.d/omnitrack.conf \
  ./usr/lib/sysusers.d/omnitrack.conf \
  ./etc/default/omnitrack \
  ./etc/omnitrack/tracker.toml \
  ./etc/omnitrack/rig.toml \
  ./usr/share/bash-completion/completions/omnitrack \
  ./usr/share/zsh/vendor-completions/_omnitrack \
  ./usr/share/fish/vendor_completions.d/omnitrack.fish \
  ./usr/share/man/man1/omnitrack.1.gz \
  ./usr/share/man/man1/omnitrack-run.1.gz \
  ./usr/share/doc/omnitrack/copyright; do
  grep -qxF "$path" <<<"$contents" || fail "no $path in the package"
done

dpkg-deb --ctrl-tarfile "$deb" | tar -x -C "$scratch"
for conffile in /etc/default/omnitrack /etc/omnitrack/tracker.toml /etc/omnitrack/rig.toml; do
  grep -qxF "$conffile" "$scratch/conffiles" || fail "$conffile is not a conffile"
done
for script in postinst prerm postrm; do
  [ -x "$scratch/$script" ] || fail "no executable $script"
done
grep -q 'systemd-sysusers omnitrack.conf' "$scratch/postinst" || fail "postinst makes no user"

root="$scratch/root"
dpkg-deb -x "$deb" "$root"
bin="$root/usr/bin/omnitrack"
version="$("$bin" --version)" || fail "omnitrack --version failed"
for source in v4l usb; do
  grep -q "sources: .*$source" <<<"$version" || fail "the binary cannot read --source $source: $version"
done
"$bin" --help | grep -q '^Usage: omnitrack' || fail "omnitrack --help printed no usage"
"$bin" manpage --dir "$scratch/pages" 2>/dev/null
made="$(cd "$scratch/pages" && ls | sed 's/$/.gz/' | sort)"
shipped="$(ls "$root/usr/share/man/man1" | sort)"
[ "$made" = "$shipped" ] || fail "manual pages differ from the binary's: $(diff <(echo "$made") <(echo "$shipped") | tr '\n' ' ')"

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
echo "check-deb.sh: $deb: $(grep -c . <<<"$contents") entries, every promised file there; $version"
