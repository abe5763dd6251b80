#!/usr/bin/env python3
"""Static file server on loopback for the web player: python3's http.server plus HTTP Range
(single ranges, 206 + Content-Range), which the player uses to fetch the GOP index and then one
GOP at a time. `--no-range` ignores Range (200, whole file) to test the player's fallback.

    python3 web/player/serve.py [--port 8768] [--dir .] [--no-range]
"""
import argparse
import http.server
import os
import re


class Handler(http.server.SimpleHTTPRequestHandler):
    ranges = True

    def end_headers(self):
        self.send_header("Accept-Ranges", "bytes" if self.ranges else "none")
        self.send_header("Cache-Control", "no-store")
        super().end_headers()

    def log_message(self, *args):
        pass

    def send_head(self):
        m = re.fullmatch(r"bytes=(\d*)-(\d*)", self.headers.get("Range", "").strip())
        path = self.translate_path(self.path)
        if not self.ranges or not m or not os.path.isfile(path):
            return super().send_head()
        size = os.path.getsize(path)
        a, b = m.groups()
        if a == "":  # suffix range: the last b bytes
            start, end = max(0, size - int(b)), size - 1
        else:
            start, end = int(a), min(int(b) if b else size - 1, size - 1)
        if start >= size or start > end:
            self.send_response(416)
            self.send_header("Content-Range", f"bytes */{size}")
            self.end_headers()
            return None
        f = open(path, "rb")
        f.seek(start)
        self.send_response(206)
        self.send_header("Content-Type", self.guess_type(path))
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(end - start + 1))
        self.end_headers()
        self._remaining = end - start + 1
        return f

    def copyfile(self, source, outputfile):
        n = getattr(self, "_remaining", None)
        if n is None:
            return super().copyfile(source, outputfile)
        self._remaining = None
        while n > 0:
            buf = source.read(min(n, 1 << 20))
            if not buf:
                break
            outputfile.write(buf)
            n -= len(buf)


Handler.extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map,
                          ".wasm": "application/wasm", ".js": "text/javascript", ".mjs": "text/javascript"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, default=8768)
    ap.add_argument("--dir", default=".")
    ap.add_argument("--no-range", action="store_true")
    a = ap.parse_args()
    Handler.ranges = not a.no_range
    os.chdir(a.dir)
    srv = http.server.ThreadingHTTPServer(("127.0.0.1", a.port), Handler)
    print(f"serving {os.getcwd()} on http://127.0.0.1:{a.port}/ (Range {'on' if Handler.ranges else 'off'})", flush=True)
    srv.serve_forever()


if __name__ == "__main__":
    main()
