"""Write simbridge/msgs/definitions.txt: rosbags' message definitions, as simbridge ships them.

    .venv/bin/python scripts/definitions.py          # (re)write the file
    .venv/bin/python scripts/definitions.py --check  # exit 1 if the file is not what it writes

Run it after upgrading rosbags or editing a ``.msg`` text simbridge registers at start or with
its interfaces (``tests/msgs/test_definitions.py`` fails until then). What the file holds and
why: :mod:`simbridge.msgs.definitions`. Everything in it comes from the installed rosbags:

* ``standard``: the definitions of rosbags' latest ROS 2 store (``get_typestore``), as given;
* ``parsed``: each text the robot graph registers (the default world's, built headless) and
  simbridge's service/action interfaces, registered in a rosbags store the way the registry
  did before the file existed (``get_types_from_msg``, then ``Typestore.register``), with the
  definition that store holds afterwards.
"""

from __future__ import annotations

import argparse
import json
import sys
from importlib.metadata import version
from pathlib import Path
from typing import Any


ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def _plain(value: Any) -> Any:
    """JSON's form of a rosbags definition: tuples as lists, nodetypes as ints."""
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, int) and not isinstance(value, bool):
        return int(value)
    return value


def texts() -> dict[str, str]:
    """Every message text a default run registers, and the interfaces': name -> .msg text."""
    from simbridge.headless import Simulation

    registry = Simulation().graph.registry
    registry.services  # noqa: B018 (adds the pending interfaces)
    return dict(registry.texts)


def standard() -> dict[str, Any]:
    """The file's content without the texts: rosbags' store as given."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.LATEST)
    definitions = {name: _plain(store.fielddefs[name]) for name in sorted(store.fielddefs)}
    return {"rosbags": version("rosbags"), "standard": definitions, "parsed": {}}


def build() -> dict[str, Any]:
    """The file's content, from the installed rosbags and simbridge's texts.

    simbridge's registry (which gives the texts) reads the file: the one there is used, or one
    without the texts, written first, when there is none (its texts are then parsed by rosbags).
    """
    from rosbags.typesys import Stores, get_typestore
    from rosbags.typesys.msg import get_types_from_msg

    store = get_typestore(Stores.LATEST)
    content = standard()
    parsed: dict[str, Any] = content["parsed"]
    for name, text in texts().items():
        pkg, _kind, typename = name.split("/")
        key = f"{pkg}/msg/{typename}"
        types = get_types_from_msg(text or "\n", key)
        if list(types) != [key]:
            msg = f"{name}: the text defines {sorted(types)}, expected only {key}"
            raise SystemExit(msg)
        store.register({name: types[key]})
        parsed[name] = [text, *_plain(store.fielddefs[name])]
    content["parsed"] = dict(sorted(parsed.items()))
    return content


def render(content: dict[str, Any]) -> str:
    """One type a line, ``KIND NAME JSON`` (a change to one type is one line of the diff)."""
    lines = [
        f"# simbridge.msgs.definitions: written by scripts/definitions.py from rosbags "
        f"{content['rosbags']}; do not edit",
        *(
            f"standard {k} {json.dumps(v, separators=(',', ':'))}"
            for k, v in content["standard"].items()
        ),
        *(
            f"parsed {k} {json.dumps(v, separators=(',', ':'))}"
            for k, v in content["parsed"].items()
        ),
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write the file, or with --check compare it with what would be written."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    from simbridge.msgs.definitions import DATA

    if args.check:
        if not DATA.exists() or DATA.read_text() != render(build()):
            print(f"{DATA.relative_to(ROOT)} is out of date: run scripts/definitions.py")
            return 1
        return 0
    if not DATA.exists():
        DATA.write_text(render(standard()))
    DATA.write_text(render(build()))
    print(f"wrote {DATA.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
