"""Validates every sample the encoder writes against the published OpenTrackIO JSON schema.

Usage: validate_opentrackio.py SAMPLES_BINARY SCHEMA.json — the binary prints one JSON sample a
line; any sample that fails names the failing field and the test fails.
"""
import json
import subprocess
import sys

import jsonschema


def main():
    binary, schema_path = sys.argv[1], sys.argv[2]
    with open(schema_path, encoding="utf-8") as f:
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
