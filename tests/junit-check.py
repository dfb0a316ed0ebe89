#!/usr/bin/env python3
"""A JUnit XML file as a CI server reads it: validated against junit-10.xsd (the schema of
Jenkins' xUnit plug-in, which pytest's own tests use) with xmlschema, then read by junitparser,
a reader that is not ours. Prints what it read as JSON: the counts, and each failed case with
its message and text. Exit status 1 when the file is not valid, or when its stated totals
disagree with the cases read.

Usage: junit-check.py FILE.xml junit-10.xsd
"""
import json
import sys

import junitparser
import xmlschema


def main():
    xml, xsd = sys.argv[1], sys.argv[2]
    try:
        xmlschema.XMLSchema(xsd).validate(xml)
    except xmlschema.XMLSchemaValidationError as e:
        print(f"{xml}: not valid by {xsd}: {e.reason} at {e.path}", file=sys.stderr)
        return 1
    doc = junitparser.JUnitXml.fromfile(xml)
    suites = [doc] if isinstance(doc, junitparser.TestSuite) else list(doc)
    tests = failures = skipped = 0
    failed = []
    for suite in suites:
        for case in suite:
            tests += 1
            for r in case.result:
                if isinstance(r, (junitparser.Failure, junitparser.Error)):
                    failures += 1
                    failed.append({"suite": suite.name, "case": case.name,
                                   "classname": case.classname, "time": case.time,
                                   "message": r.message, "text": r.text})
                elif isinstance(r, junitparser.Skipped):
                    skipped += 1
    root = {k: doc._elem.get(k) for k in ("tests", "failures", "errors")}
    out = {"suites": len(suites), "tests": tests, "failures": failures, "skipped": skipped,
           "failed": failed}
    print(json.dumps(out, indent=1))
    if root["tests"] is not None and int(root["tests"]) != tests:
        print(f"{xml}: says tests=\"{root['tests']}\", {tests} cases read", file=sys.stderr)
        return 1
    stated = int(root["failures"] or 0) + int(root["errors"] or 0)
    if root["failures"] is not None and stated != failures:
        print(f"{xml}: says {stated} failed, {failures} read", file=sys.stderr)
        return 1
    print(f"{xml}: valid by {xsd}; junitparser reads {len(suites)} suites, {tests} cases, "
          f"{failures} failed, {skipped} skipped", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
