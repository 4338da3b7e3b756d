"""Checks shared by the report tests: strict HTML5 parsing, no external URL, embedded figures."""
from __future__ import annotations

import base64
import re
from pathlib import Path
from xml.etree.ElementTree import Element

import html5lib

#: attributes that load or link something
URL_ATTRIBUTES = ("src", "href", "action", "data", "poster", "srcset", "formaction")


def parse(path: Path) -> Element:
    """The page as an ElementTree; html5lib's strict mode raises on any HTML5 parse error."""
    return html5lib.HTMLParser(strict=True, namespaceHTMLElements=False).parse(path.read_bytes())


def assert_self_contained(path: Path, root: Element) -> None:
    """Nothing outside the file: every URL-valued attribute is a data: URI or a fragment, no URL in the text."""
    for el in root.iter():
        for attr in URL_ATTRIBUTES:
            value = el.get(attr)
            if value is not None:
                assert value.startswith(("data:", "#")), f"{el.tag} {attr}={value[:80]!r}"
        assert el.tag not in ("link", "iframe", "object", "embed"), el.tag
        if el.tag == "style" and el.text:
            assert "url(" not in el.text and "@import" not in el.text
    text = path.read_text(encoding="utf-8")
    assert not re.search(r"(https?|ftp)://|//[a-z0-9.-]+\.[a-z]{2,}/", text, re.IGNORECASE)


def embedded_images(root: Element) -> list[bytes]:
    """The PNG bytes of every <img> (each must be a base64 data URI)."""
    out = []
    for img in root.iter("img"):
        src = img.get("src")
        assert src.startswith("data:image/png;base64,") and img.get("alt")
        out.append(base64.b64decode(src.split(",", 1)[1], validate=True))
    return out


def cells(row: Element) -> list[str]:
    return ["".join(td.itertext()).strip() for td in row.findall("td")]


def numbers(text: str) -> list[float]:
    """The numbers in a cell, in order (``[0.1, 0.2]``, ``+5.02 %`` -> 5.02)."""
    return [float(x) for x in re.findall(r"[-+]?\d+(?:\.\d*)?(?:e[-+]?\d+)?", text)]
