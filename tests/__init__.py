"""vivbench's test suite.

``tests/<subpackage>/`` holds the tests of ``vivbench/<subpackage>/``; ``tests/project/`` the checks
of the repository as a whole (layout, module size, the tolerance lint, the README and the documents'
code). ``tests/helpers.py`` is the shared tolerance helper (and the repository's root, ``REPO``);
``tests/conftest.py`` the session fixtures of simulated data.
"""
