"""MkDocs hooks of the documentation site (``mkdocs.yml``: ``hooks: [docs/hooks.py]``).

- The API reference is generated from the package: one page per subpackage (``api/<name>.md``, every module in
  it rendered by mkdocstrings from its docstrings) and ``api/index.md`` listing them, so a module that is added
  or moved is documented without editing a page.
- ``<!-- include ../BENCHMARKS.md -->`` on a line of its own puts that file's text in the page (links rewritten
  to stay right from the page).
- A link from a page to a repository file outside ``docs/`` (``../studies/gpu/README.md``) must name a file
  that exists; it becomes a link into the repository (``repo_url``'s ``blob/main/`` when set, else the file in
  the checkout, beside ``site/``). A missing one is a warning, so ``mkdocs build --strict`` fails on it, as
  mkdocs itself fails on a broken link between pages.
- The relative links of ``README.md`` and ``BENCHMARKS.md`` are checked the same way (they are not pages).
"""

from __future__ import annotations

import logging
import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.hooks.freespace")

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "freespace"
DOCS = ROOT / "docs"  # mkdocs.yml's docs_dir
CHECKED = ("README.md", "BENCHMARKS.md")  # repository files whose links are checked, not rendered
_REPO = "repo:"  # scheme of a link into the repository while the page is rendered
# [text](target) and ![alt](target), not inside `code`; the target without a title
_LINK = re.compile(r"(?<!`)(!?\[[^\]\n]*\]\()([^)\s]+)((?:\s+\"[^\"]*\")?\))")
_FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
_INCLUDE = re.compile(r"^<!-- include (\S+) -->$", re.M)


def _modules() -> dict[str, list[str]]:
    """``{page name: [module, ...]}``: one page per subpackage of ``freespace``, one for the root modules."""
    pages: dict[str, list[str]] = {"freespace": ["freespace"]}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        if len(parts) == 1 or parts[-1].startswith("_") and len(parts) > 2:
            continue
        page = parts[1] if len(parts) > 2 or (path.name == "__init__.py") else "freespace"
        pages.setdefault(page, []).append(".".join(parts))
    return pages


def _is_package(module: str) -> bool:
    return (ROOT.joinpath(*module.split(".")) / "__init__.py").exists()


def on_files(files: Files, config) -> Files:
    pages = _modules()
    index = ["# API reference", "",
             "Generated from the docstrings by mkdocstrings: every module of the package, one page per "
             "subpackage. The manual's pages say what the commands do; these pages say what each function "
             "takes and returns (shapes, units, conventions).", "",
             "| page | modules |", "|---|---|"]
    for page, modules in sorted(pages.items(), key=lambda kv: (kv[0] != "freespace", kv[0])):
        title = "freespace (root modules)" if page == "freespace" else f"freespace.{page}"
        # a package's page shows its own docstring; its modules follow, each with its members
        body = [f"# {title}", ""] + [f"::: {m}\n    options:\n      members: false\n" if _is_package(m)
                                     else f"::: {m}\n" for m in modules]
        files.append(File.generated(config, f"api/{page}.md", content="\n".join(body)))
        index.append(f"| [{title}]({page}.md) | {', '.join(f'`{m}`' for m in modules)} |")
    files.append(File.generated(config, "api/index.md", content="\n".join(index) + "\n"))
    return files


def _rewrite(text: str, source_dir: Path, page_dir: Path, where: str) -> str:
    """Links of ``text`` (written beside ``source_dir``) made right from ``page_dir``; those leaving the docs
    folder become ``repo:PATH`` and must exist."""
    docs = DOCS

    def fix(m: re.Match) -> str:
        target = m.group(2)
        if re.match(r"[a-z][a-z0-9+.-]*:|#|/", target):
            return m.group(0)
        path, _, anchor = target.partition("#")
        resolved = (source_dir / path).resolve()
        try:
            resolved.relative_to(docs)
            inside = True
        except ValueError:
            inside = False
        if inside:
            new = posixpath.relpath(resolved.as_posix(), page_dir.resolve().as_posix())
            return f"{m.group(1)}{new}{'#' + anchor if anchor else ''}{m.group(3)}"
        if not resolved.exists():
            log.warning(f"{where} links to '{target}', which is not in the repository")
        try:
            rel = resolved.relative_to(ROOT).as_posix()
        except ValueError:
            log.warning(f"{where} links to '{target}', outside the repository")
            return m.group(0)
        return f"{m.group(1)}{_REPO}{rel}{'#' + anchor if anchor else ''}{m.group(3)}"

    out, last = [], 0
    for fence in _FENCE.finditer(text):  # leave code blocks alone
        out.append(_LINK.sub(fix, text[last:fence.start()]))
        out.append(fence.group(0))
        last = fence.end()
    out.append(_LINK.sub(fix, text[last:]))
    return "".join(out)


def on_pre_build(config) -> None:
    for name in CHECKED:
        path = ROOT / name
        if path.exists():
            _rewrite(path.read_text(encoding="utf-8"), ROOT, ROOT / "docs", name)


def on_page_markdown(markdown: str, page, config, files) -> str:
    source = Path(page.file.abs_src_path) if page.file.abs_src_path else Path(config["docs_dir"]) / page.file.src_uri
    page_dir = source.parent

    def include(m: re.Match) -> str:
        path = (page_dir / m.group(1)).resolve()
        if not path.exists():
            log.warning(f"{page.file.src_uri} includes '{m.group(1)}', which is not in the repository")
            return ""
        text = path.read_text(encoding="utf-8")
        text = re.sub(r"\A# .*\n", "", text)  # the page has its own title
        return _rewrite(text, path.parent, page_dir, f"{path.relative_to(ROOT)} (in {page.file.src_uri})")

    markdown = _INCLUDE.sub(include, markdown)
    return _rewrite(markdown, page_dir, page_dir, page.file.src_uri)


def on_page_content(html: str, page, config, files) -> str:
    repo_url = (config.get("repo_url") or "").rstrip("/")
    depth = page.file.url.count("/")
    site = Path(config["site_dir"]).resolve()
    up = posixpath.relpath(ROOT.as_posix(), site.as_posix())

    def link(m: re.Match) -> str:
        rel = m.group(2)
        if repo_url:
            return f'{m.group(1)}"{repo_url}/blob/main/{rel}"'
        return f'{m.group(1)}"{"../" * depth}{up}/{rel}"'

    return re.sub(r'((?:href|src)=)"' + re.escape(_REPO) + r'([^"]*)"', link, html)


def on_config(config):
    """The nav's ``API reference`` entry becomes the index and one page per subpackage."""
    pages = sorted(_modules(), key=lambda p: (p != "freespace", p))
    for i, item in enumerate(config["nav"] or []):
        if isinstance(item, dict) and item.get("API reference") == "api/index.md":
            config["nav"][i] = {"API reference": ["api/index.md"] + [
                {("freespace (root)" if p == "freespace" else f"freespace.{p}"): f"api/{p}.md"} for p in pages]}
    return config
