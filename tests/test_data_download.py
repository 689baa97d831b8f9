"""data_tools.download against a real local HTTP server (no internet): resume, restart,
checksums, interrupted transfers, HTTP errors, offline, and ZIP checks."""

import hashlib
import http.server
import io
import re
import socket
import threading
import zipfile

import pytest

from data_tools.download import DownloadResult, download_file, file_sha256, verify_zip
from data_tools.errors import DownloadError, InputFileError, TpvpError

PAYLOAD = bytes(range(256)) * 4096 + b"tail"  # 1 MiB + 4 bytes, not a multiple of the chunk size
PAYLOAD_SHA = hashlib.sha256(PAYLOAD).hexdigest()
CHUNK = 64 * 1024


class _State:
    """What the server serves and how it misbehaves; ``requests`` records the Range headers."""

    def __init__(self):
        self.files = {"/data.bin": PAYLOAD}
        self.ignore_range = False
        self.drop_after = None  # send only this many body bytes of the next response, then hang up
        self.length_delta = 0  # added to the true Content-Length (a lying server)
        self.requests = []  # Range header of each GET (None when absent)


class _Handler(http.server.BaseHTTPRequestHandler):
    def log_message(self, *args):  # keep the test output clean
        pass

    def do_GET(self):
        state = self.server.state
        rng = self.headers.get("Range")
        state.requests.append(rng)
        data = state.files.get(self.path)
        if data is None:
            self.send_error(404, "Not Found")
            return
        start, status = 0, 200
        if rng and not state.ignore_range:
            start = int(re.fullmatch(r"bytes=(\d+)-", rng).group(1))
            if start >= len(data):
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{len(data)}")
                self.send_header("Content-Length", "0")
                self.end_headers()
                return
            status = 206
        body = data[start:]
        self.send_response(status)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Length", str(len(body) + state.length_delta))
        if status == 206:
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        self.end_headers()
        if state.drop_after is not None:
            body, state.drop_after = body[:state.drop_after], None  # one-shot
        self.wfile.write(body)
        # HTTP/1.0: the connection closes after the response, also after a short body.


@pytest.fixture(scope="module")
def _server():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    server.daemon_threads = True
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield server
    server.shutdown()
    server.server_close()


@pytest.fixture
def server(_server):
    """The module's server with a fresh state; ``server.url(path)`` builds a URL."""
    _server.state = _State()
    _server.url = lambda path="/data.bin": f"http://127.0.0.1:{_server.server_address[1]}{path}"
    return _server


def test_full_download_checks_sha256_and_writes_sidecar(server, tmp_path):
    dest = tmp_path / "sub" / "data.bin"
    result = download_file(server.url(), dest, sha256=PAYLOAD_SHA.upper(),
                           expected_size=len(PAYLOAD), chunk_size=CHUNK, progress=False)
    assert result == DownloadResult(dest, len(PAYLOAD), PAYLOAD_SHA, resumed=False)
    assert dest.read_bytes() == PAYLOAD
    assert not (tmp_path / "sub" / "data.bin.part").exists()
    assert (tmp_path / "sub" / "data.bin.sha256").read_text() == f"{PAYLOAD_SHA}  data.bin\n"
    assert server.state.requests == [None]
    assert file_sha256(dest) == PAYLOAD_SHA

    # A verified file with its sidecar is returned without asking the server again.
    again = download_file(server.url(), dest, sha256=PAYLOAD_SHA, progress=False)
    assert again.sha256 == PAYLOAD_SHA and not again.resumed
    assert server.state.requests == [None]

    # Another expected checksum is not vouched for by the sidecar: downloaded again, rejected,
    # and the verified file stays as it was.
    with pytest.raises(DownloadError, match="SHA-256 mismatch"):
        download_file(server.url(), dest, sha256="1" * 64, progress=False)
    assert server.state.requests == [None, None]
    assert dest.read_bytes() == PAYLOAD


def test_progress_bar_runs(server, tmp_path, capsys):
    result = download_file(server.url(), tmp_path / "data.bin", chunk_size=CHUNK, progress=True)
    assert result.size == len(PAYLOAD)
    assert "data.bin" in capsys.readouterr().err  # tqdm writes its bar (with the name) to stderr


def test_resume_from_partial_file_sends_range(server, tmp_path):
    dest = tmp_path / "data.bin"
    cut = 300_001
    (tmp_path / "data.bin.part").write_bytes(PAYLOAD[:cut])
    result = download_file(server.url(), dest, sha256=PAYLOAD_SHA, chunk_size=CHUNK, progress=False)
    assert server.state.requests == [f"bytes={cut}-"]
    assert result.resumed and result.size == len(PAYLOAD) and result.sha256 == PAYLOAD_SHA
    assert dest.read_bytes() == PAYLOAD


def test_server_ignoring_range_restarts_from_zero(server, tmp_path):
    server.state.ignore_range = True
    dest = tmp_path / "data.bin"
    (tmp_path / "data.bin.part").write_bytes(b"stale bytes that must not stay in front")
    result = download_file(server.url(), dest, sha256=PAYLOAD_SHA, progress=False)
    assert server.state.requests[0].startswith("bytes=")  # it asked to resume ...
    assert not result.resumed  # ... got a 200 and started over
    assert dest.read_bytes() == PAYLOAD


def test_complete_part_answered_416_is_accepted(server, tmp_path):
    dest = tmp_path / "data.bin"
    (tmp_path / "data.bin.part").write_bytes(PAYLOAD)
    result = download_file(server.url(), dest, sha256=PAYLOAD_SHA, progress=False)
    assert server.state.requests == [f"bytes={len(PAYLOAD)}-"]
    assert result.resumed and dest.read_bytes() == PAYLOAD


def test_checksum_mismatch_removes_part_and_writes_nothing(server, tmp_path):
    dest = tmp_path / "data.bin"
    wrong = "0" * 64
    with pytest.raises(DownloadError) as err:
        download_file(server.url(), dest, sha256=wrong, progress=False)
    message = str(err.value)
    assert "data.bin" in message and wrong in message and PAYLOAD_SHA in message
    assert "\n" not in message
    assert not dest.exists() and not (tmp_path / "data.bin.part").exists()
    assert not (tmp_path / "data.bin.sha256").exists()


def test_dropped_connection_keeps_part_and_next_call_resumes(server, tmp_path):
    dest = tmp_path / "data.bin"
    server.state.drop_after = 200_000
    with pytest.raises(DownloadError, match="interrupted after 200000 of 1048580 bytes"):
        download_file(server.url(), dest, sha256=PAYLOAD_SHA, chunk_size=CHUNK, progress=False)
    assert not dest.exists()
    assert (tmp_path / "data.bin.part").read_bytes() == PAYLOAD[:200_000]

    result = download_file(server.url(), dest, sha256=PAYLOAD_SHA, chunk_size=CHUNK, progress=False)
    assert server.state.requests == [None, "bytes=200000-"]
    assert result.resumed and dest.read_bytes() == PAYLOAD


def test_size_mismatch_with_expected_size(server, tmp_path):
    server.state.length_delta = -10  # the server announces 10 bytes fewer than the file has
    with pytest.raises(DownloadError, match=f"reports {len(PAYLOAD) - 10} bytes, expected "
                                            f"{len(PAYLOAD)}"):
        download_file(server.url(), tmp_path / "data.bin", expected_size=len(PAYLOAD),
                      progress=False)
    assert not (tmp_path / "data.bin").exists()


def test_http_404_names_status_and_url(server, tmp_path):
    url = server.url("/missing.zip")
    with pytest.raises(DownloadError) as err:
        download_file(url, tmp_path / "missing.zip", progress=False)
    assert "404" in str(err.value) and url in str(err.value)
    assert not (tmp_path / "missing.zip").exists()


def test_unreachable_host_is_one_offline_line(tmp_path):
    with socket.socket() as sock:  # a free local port that nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    url = f"http://127.0.0.1:{port}/Pheno4D.zip"
    with pytest.raises(DownloadError) as err:
        download_file(url, tmp_path / "Pheno4D.zip", timeout=2, progress=False)
    message = str(err.value)
    assert isinstance(err.value, TpvpError) and "\n" not in message
    assert message.startswith("cannot reach 127.0.0.1 (") and "offline?" in message
    assert url in message and "by hand" in message


def test_bad_arguments_are_one_line_errors(tmp_path):
    with pytest.raises(DownloadError, match="64 hexadecimal digits"):
        download_file("http://127.0.0.1/x", tmp_path / "x", sha256="abc", progress=False)
    with pytest.raises(DownloadError, match="only http:// and https://"):
        download_file("ftp://example.org/x", tmp_path / "x", progress=False)


def _zip_bytes() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        zf.writestr("Pheno4D/Maize01/M01_0313_a.txt", b"A" * 5000)
        zf.writestr("Pheno4D/Tomato01/T01_0305.txt", b"1 2 3\n" * 100)
        zf.writestr("Pheno4D/README.txt", b"readme")
    return buf.getvalue()


def test_verify_zip_good_truncated_and_corrupt(tmp_path):
    data = _zip_bytes()
    good = tmp_path / "good.zip"
    good.write_bytes(data)
    assert verify_zip(good) == 3

    truncated = tmp_path / "truncated.zip"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputFileError, match=r"truncated\.zip: not a readable ZIP archive"):
        verify_zip(truncated)

    corrupt = tmp_path / "corrupt.zip"
    corrupt.write_bytes(data.replace(b"A" * 5000, b"A" * 4999 + b"B"))
    with pytest.raises(InputFileError, match=r"corrupt\.zip::Pheno4D/Maize01/M01_0313_a\.txt: "
                                             r"corrupt ZIP member"):
        verify_zip(corrupt)

    with pytest.raises(InputFileError, match="file not found"):
        verify_zip(tmp_path / "absent.zip")
