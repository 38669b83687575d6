"""Write the README's headline table from the committed reference report (``make readme``).

Usage: ``python tools/update_readme.py [README.md] [reports/default/report.md]``. The table
goes between the README's markers (:data:`vivbench.report.HEADLINE_BEGIN` and ``_END``);
``tests/project/test_readme.py`` fails when the README's table differs from what this writes.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from vivbench.report import headline_table, readme_with_headline


def main(argv: list[str]) -> int:
    readme = Path(argv[0] if argv else "README.md")
    report = Path(argv[1] if len(argv) > 1 else "reports/default/report.md")
    try:
        text = readme_with_headline(readme.read_text(encoding="utf-8"),
                                    headline_table(report.read_text(encoding="utf-8")))
    except (OSError, ValueError) as exc:
        print(f"update_readme: {exc}", file=sys.stderr)
        return 2
    fd, tmp = tempfile.mkstemp(dir=readme.parent, prefix=f".{readme.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.chmod(tmp, readme.stat().st_mode)
    os.replace(tmp, readme)
    print(f"wrote the headline table of {readme} from {report}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
