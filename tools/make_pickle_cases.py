#!/usr/bin/env python3
"""Pickles from Python's own pickler for formats/src/torch_pickle.rs's unit tests, printed as Rust
byte strings after what they hold: opcodes torch's checkpoints can hold that the fixtures do not
(NEWOBJ_EX, non-ASCII SHORT_BINUNICODE keys).

Usage: python3 tools/make_pickle_cases.py   (any Python 3.8+; the standard library only)
"""
import copyreg
import pickle


class Point:
    """An object pickled through NEWOBJ_EX: `Point.__new__(Point, 3, y=4)`."""

    def __init__(self, x, y):
        self.x, self.y = x, y

    def __reduce_ex__(self, protocol):
        return (copyreg.__newobj_ex__, (Point, (self.x,), {"y": self.y}))


def rust(data):
    return 'b"' + "".join(chr(b) if 32 <= b < 127 and chr(b) not in '"\\' else f"\\x{b:02x}" for b in data) + '"'


def main():
    for what, value in (("NEWOBJ_EX of __main__.Point, args (3,), kwargs {'y': 4}", Point(3, 4)),
                        ("{'gewicht·ä': 1}", {"gewicht·ä": 1})):
        print(f"// pickle.dumps({what}, protocol=4)\n{rust(pickle.dumps(value, protocol=4))}")


if __name__ == "__main__":
    main()
