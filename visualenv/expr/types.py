"""Static types of expression values: numbers, conditions and fixed-size vectors."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Type:
    kind: str  # "num" | "bool" | "vec"
    size: int = 0  # vectors only; 0 in a signature means any size

    def __str__(self) -> str:
        if self.kind == "num":
            return "a number"
        if self.kind == "bool":
            return "a condition (true/false)"
        return f"a vector of {self.size}" if self.size else "a vector"


NUM = Type("num")
BOOL = Type("bool")
VEC = Type("vec")


def vec(n: int) -> Type:
    return Type("vec", n)
