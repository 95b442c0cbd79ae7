"""HTTP calls to a Kitchen-R server's `/api/v1` (urllib only) and its errors in words."""

import json
import urllib.error
import urllib.request
from email.utils import parsedate_to_datetime


class ApiError(Exception):
    """A refused or failed request. `transient`: polling again may help (unreachable, 5xx, 429)."""

    def __init__(self, message, status=None, transient=False, retry_after=None):
        super().__init__(message)
        self.status = status
        self.transient = transient
        self.retry_after = retry_after


def error_message(status, body):
    """The server's message with status, error code and request id (quote it when reporting)."""
    try:
        v = json.loads(body)
    except ValueError:
        v = None
    if not isinstance(v, dict) or not isinstance(v.get("error"), str):
        text = (body or "").strip()
        return "%s (HTTP %d)" % (text, status) if text else "the server answered HTTP %d" % status
    extra = []
    if isinstance(v.get("code"), str):
        extra.append("code " + v["code"])
    if isinstance(v.get("request_id"), str):
        extra.append("request id " + v["request_id"])
    tail = " [%s]" % ", ".join(extra) if extra else ""
    return "%s (HTTP %d)%s" % (v["error"], status, tail)


class Response:
    def __init__(self, status, headers, body):
        self.status = status
        self.headers = headers
        self.body = body

    def json(self):
        try:
            return json.loads(self.body.decode("utf-8"))
        except ValueError:
            raise ApiError("the server's answer is not JSON") from None

    def text(self):
        return self.body.decode("utf-8", "replace")

    def server_now_ms(self):
        """The server's clock when it answered (its Date header), in Unix milliseconds."""
        date = self.headers.get("Date")
        if not date:
            return None
        try:
            return int(parsedate_to_datetime(date).timestamp() * 1000)
        except (TypeError, ValueError):
            return None


class Client:
    def __init__(self, server, token=None, timeout=30.0):
        self.server = server.rstrip("/")
        self.token = token
        self.timeout = timeout

    def url(self, path):
        return self.server + path

    def request(self, method, path, body=None, content_type=None, token=None):
        headers = {"Accept": "application/json", "User-Agent": "kitchen-r-client"}
        token = token if token is not None else self.token
        if token:
            headers["Authorization"] = "Bearer " + token
        data = None
        if body is not None:
            if isinstance(body, (dict, list)):
                data = json.dumps(body).encode("utf-8")
                content_type = content_type or "application/json"
            else:
                data = body if isinstance(body, bytes) else body.encode("utf-8")
            headers["Content-Type"] = content_type or "application/octet-stream"
        req = urllib.request.Request(self.url(path), data=data, headers=headers, method=method)
        try:
            with urllib.request.urlopen(req, timeout=self.timeout) as r:
                return Response(r.status, r.headers, r.read())
        except urllib.error.HTTPError as e:
            text = e.read().decode("utf-8", "replace")
            retry_after = None
            try:
                retry_after = min(max(float(e.headers.get("Retry-After", "")), 0.0), 300.0)
            except (TypeError, ValueError):
                pass
            raise ApiError(
                error_message(e.code, text),
                status=e.code,
                transient=e.code >= 500 or e.code == 429,
                retry_after=retry_after,
            ) from None
        except (urllib.error.URLError, OSError) as e:
            reason = getattr(e, "reason", e)
            raise ApiError("cannot reach the server at %s: %s" % (self.server, reason), transient=True) from e

    def get_json(self, path, token=None):
        return self.request("GET", path, token=token).json()

    def post_json(self, path, body=None, content_type=None, token=None):
        return self.request("POST", path, body, content_type, token=token).json()
