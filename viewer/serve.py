"""`make viewer`: serve the viewer page, the three.js files it imports and one model on 127.0.0.1,
and nothing else (not the repository: its .git/config, the user's scenes and bakes stay private).

    python viewer/serve.py [--port 8000] [--model scene.glb]

URLs: /viewer/index.html, main.js, moz_lightmap.js and detp_probes.js; /viewer/node_modules/three/build/ and
/viewer/node_modules/three/examples/jsm/ (the page's import map); /model/<name of the .glb>.
Anything else is 404, a folder included (no listings)."""
from __future__ import annotations

import argparse
import os
import posixpath
import sys
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

VIEWER = Path(__file__).resolve().parent
PAGE_FILES = ("index.html", "main.js", "moz_lightmap.js", "detp_probes.js")
THREE_FOLDERS = ("build", "examples/jsm")


def resolver(model: str | None):
    """`resolve(url path)`: the file it serves, or None."""
    roots = [os.path.realpath(VIEWER / "node_modules" / "three" / folder) for folder in THREE_FOLDERS]
    model_path = os.path.realpath(model) if model else None

    def resolve(url: str) -> str | None:
        path = posixpath.normpath(unquote(urlsplit(url).path))
        if model_path and path == f"/model/{os.path.basename(model_path)}":
            return model_path if os.path.isfile(model_path) else None
        if not path.startswith("/viewer/"):
            return None
        rest = path[len("/viewer/"):]
        if rest in PAGE_FILES:
            return str(VIEWER / rest)
        for folder, root in zip(THREE_FOLDERS, roots):
            prefix = f"node_modules/three/{folder}/"
            if rest.startswith(prefix):
                found = os.path.realpath(os.path.join(root, rest[len(prefix):]))
                if os.path.commonpath([found, root]) == root and os.path.isfile(found):
                    return found
        return None
    return resolve


class Handler(SimpleHTTPRequestHandler):
    """Serves only what `resolve` maps; quiet."""

    def __init__(self, *args, resolve=None, **kwargs):
        self.resolve = resolve
        super().__init__(*args, **kwargs)

    def send_head(self):
        if self.resolve(self.path) is None:
            self.send_error(404, "not served")
            return None
        return super().send_head()

    def translate_path(self, path: str) -> str:
        return self.resolve(path) or ""

    def log_message(self, *args) -> None:
        pass


def server(port: int = 0, model: str | None = None) -> ThreadingHTTPServer:
    """The server on 127.0.0.1:`port` (0: any free port), not yet serving."""
    return ThreadingHTTPServer(("127.0.0.1", port), partial(Handler, resolve=resolver(model)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--model", default=None, help="the .glb to serve as /model/<its name>")
    args = parser.parse_args(argv)
    if args.model and not os.path.isfile(args.model):
        print(f"error: --model '{args.model}' is not a file", file=sys.stderr)
        return 2
    httpd = server(args.port, args.model)
    url = f"http://127.0.0.1:{httpd.server_address[1]}/viewer/index.html"
    if args.model:
        url += f"?model=/model/{os.path.basename(os.path.realpath(args.model))}"
    print(f"open {url}  (or drop a .glb on the page; Ctrl+C stops the server)", flush=True)
    try:
        httpd.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        httpd.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
