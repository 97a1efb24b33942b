#!/usr/bin/python3
"""Every relative link of the Markdown files resolves to a file or folder in the tree.

usage: /usr/bin/python3 scripts/check_links.py [FILE.md ...]   (default: every tracked *.md)

Checks inline links and images, [text](target) and ![alt](target), and reference
definitions, [label]: target, outside fenced code blocks and inline code spans. Web
addresses (http:, https:, mailto:, ...) are not checked. An #anchor, in the page or on a
link to another Markdown file, must name one of that file's headings as GitHub spells it
(lower case, punctuation dropped, spaces as hyphens, -1, -2, ... for repeats). Prints one line
per broken link, FILE:LINE: target, and exits 1 if there is any (0 otherwise). Run by the
ctest docs_links.
"""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
DEFINITION = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")


def markdown_files(args):
    if args:
        return [Path(a).resolve() for a in args]
    try:
        listed = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others",
                                 "--exclude-standard", "*.md"], capture_output=True, check=True).stdout.decode()
        return [ROOT / f for f in listed.split("\0") if f and (ROOT / f).is_file()]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (a source archive)
        skip = ("build", ".git", "node_modules")
        return [p for p in ROOT.rglob("*.md")
                if not any(part.startswith(skip) for part in p.relative_to(ROOT).parts)]


def links(text):
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        marker = re.match(r"(```+|~~~+)", stripped)
        if marker:
            if fence is None:
                fence = marker.group(1)[0] * 3
            elif stripped.startswith(fence):
                fence = None
            continue
        if fence is not None:
            continue
        line = CODE_SPAN.sub("", line)
        for m in INLINE.finditer(line):
            yield number, m.group(1)
        m = DEFINITION.match(line)
        if m:
            yield number, m.group(1)


def slug(heading):
    text = re.sub(r"`([^`]*)`", r"\1", heading.strip())
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)  # a link in a heading: its text
    text = re.sub(r"<[^>]+>", "", text).lower()
    text = "".join(c for c in text if c.isalnum() or c in " -_")
    return text.replace(" ", "-")


_anchors = {}


def anchors(md):
    if md not in _anchors:
        found, seen, fence = set(), {}, None
        for line in md.read_text(encoding="utf-8").splitlines():
            stripped = line.lstrip()
            marker = re.match(r"(```+|~~~+)", stripped)
            if marker:
                fence = marker.group(1)[0] * 3 if fence is None else (None if stripped.startswith(fence) else fence)
                continue
            m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line) if fence is None else None
            if m:
                base = slug(m.group(1))
                n = seen.get(base, 0)
                seen[base] = n + 1
                found.add(base if n == 0 else f"{base}-{n}")
        found.update(re.findall(r"<a\s+(?:name|id)=\"([^\"]+)\"", md.read_text(encoding="utf-8")))
        _anchors[md] = found
    return _anchors[md]


def main(argv):
    broken = 0
    files = markdown_files(argv[1:])
    for md in files:
        for number, target in links(md.read_text(encoding="utf-8")):
            if SCHEME.match(target):
                continue
            path, _, anchor = target.partition("#")
            path = path.split("?", 1)[0]
            resolved = md if not path else (ROOT / path.lstrip("/")) if path.startswith("/") else (md.parent / path)
            if not resolved.exists():
                print(f"{md.relative_to(ROOT)}:{number}: {target} (no such file)")
                broken += 1
            elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved.resolve()):
                print(f"{md.relative_to(ROOT)}:{number}: {target} (no such heading in {resolved.name})")
                broken += 1
    print(f"check_links.py: {len(files)} Markdown files, {broken} broken relative link(s)", file=sys.stderr)
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
