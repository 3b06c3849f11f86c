# Helpers the scripts share (sourced from the repository root, not run).

# Sets and exports HTER, the hter binary: as given, or built in release first.
hter_bin() {
  if [[ -z "${HTER:-}" ]]; then
    cargo build --release --bin hter -q
    HTER="${CARGO_TARGET_DIR:-target}/release/hter"
  fi
  export HTER
}

# One JSON number out of a compare object: the first "key": value.
field() { grep -o "\"$1\":[-0-9.eE+]*" <<<"$2" | head -1 | cut -d: -f2; }
