"""Validates every sample the encoder writes against the published OpenTrackIO JSON schema.

Usage: validate_opentrackio.py SAMPLES_BINARY — the binary prints one JSON sample a line; any
sample that fails names the failing field and the test fails. The schema is SMPTE's, kept with the
project's shared data (opentrackio/schema.json under $PREVIS_DATA_DIR, else ../shared/data beside
the checkout); without it the test is skipped (exit 77), saying why.
"""
import json
import os
import subprocess
import sys

import jsonschema


SKIPPED = 77


def schema_path():
    """opentrackio/schema.json in the shared data folder, or None."""
    here = os.path.dirname(os.path.abspath(__file__))
    candidates = [os.environ.get("PREVIS_DATA_DIR", ""),
                  os.path.join(here, "..", "..", "..", "shared", "data")]
    for folder in candidates:
        path = os.path.join(folder, "opentrackio", "schema.json")
        if folder and os.path.isfile(path):
            return path
    return None


def main():
    binary = sys.argv[1]
    path = schema_path()
    if path is None:
        print("skipped: no opentrackio/schema.json in the shared data (set PREVIS_DATA_DIR to the "
              "folder holding it, or put ../shared/data beside the checkout)")
        return SKIPPED
    with open(path, encoding="utf-8") as f:
        schema = json.load(f)
    validator_class = jsonschema.validators.validator_for(schema)
    validator_class.check_schema(schema)
    validator = validator_class(schema)
    lines = subprocess.run([binary], check=True, capture_output=True, text=True).stdout.splitlines()
    if not lines:
        print(f"{binary} wrote no samples", file=sys.stderr)
        return 1
    failures = 0
    for number, line in enumerate(lines, 1):
        for error in validator.iter_errors(json.loads(line)):
            failures += 1
            path = "/".join(str(p) for p in error.absolute_path)
            print(f"sample {number}: {path}: {error.message}", file=sys.stderr)
    print(f"{len(lines)} samples checked against {schema.get('$id')}, {failures} errors")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
