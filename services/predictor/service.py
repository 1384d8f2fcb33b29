"""The predictor: a stateless Zenoh queryable answering prediction requests (docs/semantics.md §1, §6).

A :class:`~skinet.wire.messages.PredictRequest` arrives on
``skinet/<system>/predict/<client>`` with the live marking and the digest of the monitor's model.  An instance that does
not know the digest fetches the :class:`~skinet.wire.messages.ModelBundle` from
``skinet/<system>/model/<digest>``, checks that the bundle hashes to the digest
before anything is built (a sha256 of its text) and keeps the bundle in a small LRU
cache.  Building the nets, exploring from the marking and computing the replies'
risks happen in worker processes (:mod:`services.predictor.sandbox`) under the request's
budget and an address-space limit, so a hostile model costs an instance at most its
limits.  Every failure is answered with ``ok=False`` and a one-line ``error``
(docs/semantics.md §7: bad input never crashes a service).

Threading: Zenoh runs query callbacks on its own threads, and a ``get`` issued from
inside one (the model fetch) may deadlock.  The callback therefore only decodes the
request (cheap) and hands valid ones to a bounded worker pool; when the pool is full
it answers ``busy`` at once rather than holding the caller's ``get`` open.  Workers
finish every query with ``with query:`` so the caller's ``get`` returns as soon as
the reply is sent (ZENOH.md).

Per-client rate limit (issue 14): ``<client>`` is the querier's router login (the
access control lets user ``U`` query only ``.../predict/U``); each client has a
token bucket (:class:`~services.common.ratelimit.RateLimiter`, ``rate_limit``
requests/s; new client names share a budget of as many names/s, issue 31), and a query over it is
answered at once with ``ok=False`` and ``rate limited: ...``, before it is even decoded, so a flooding
client neither queues behind nor ahead of the others.  ``max_pending`` still bounds the whole
instance, and one client may hold at most half of it (``busy: client ... has its
share``), so requests that are slow to answer cannot fill it either.

Load spreading (docs/semantics.md §7): besides the shared key every instance answers on its own
key ``skinet/<system>/predict/<client>/<id>``, found through its liveliness token.  There it
first replies an empty payload when it admits a request, then another every
:data:`HEARTBEAT` seconds until the answer: a client that hears nothing for a few
heartbeats knows the instance froze and asks another one, long before the query
timeout or the liveliness lease.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter, OrderedDict
from concurrent.futures import ThreadPoolExecutor

import zenoh

from services.common.ratelimit import OK, PREDICT_RATE_LIMIT as RATE_LIMIT, RateLimiter
from services.common.zenoh_config import undeclare
from services.predictor.sandbox import Worker, WorkerError
from skinet.verify.explore import DEFAULT_MEMORY_LIMIT
from skinet.wire import keys
from skinet.wire.codec import DecodeError, decode, encode
from skinet.wire.convert import bundle_digest
from skinet.wire.limits import MAX_PREDICT_REQUEST
from skinet.wire.messages import ModelBundle, PredictReply, PredictRequest

log = logging.getLogger("skinet.predictor")
HEARTBEAT = 0.1  # seconds between "working" replies on the instance key (schemas/README.md)


class FetchError(Exception):
    """The model of a digest could not be obtained; ``unknown``: nobody serves it."""

    def __init__(self, message: str, unknown: bool = False):
        super().__init__(message)
        self.unknown = unknown


def _one_line(text: str) -> str:
    return "; ".join(line.strip() for line in text.splitlines() if line.strip()) or "unknown error"


class Predictor:
    """One predictor instance on a session; see :func:`start_predictor`."""

    def __init__(
        self,
        session: zenoh.Session,
        instance_id: str,
        *,
        workers: int = 2,
        max_pending: int = 8,
        cache_size: int = 4,
        fetch_timeout: float = 2.0,
        max_budget: float = 10.0,
        memory_limit: int = DEFAULT_MEMORY_LIMIT,
        memory_mb: int = 2048,
        grace: float = 1.0,
        max_bundle: int = 1 << 20,
        max_request: int = MAX_PREDICT_REQUEST,
        rate_limit: float = RATE_LIMIT,
        rate_burst: float | None = None,
    ):
        self.session = session
        self.instance_id = keys.check_chunk(instance_id, "instance id")
        self.fetch_timeout = fetch_timeout
        self.max_budget = max_budget
        # Each worker may hold one forecast: the process limit is shared between them.
        self.memory_limit = memory_limit // max(1, workers)
        self.cache_size = cache_size
        self.grace = grace
        self.max_bundle = max_bundle
        self.max_request = max_request
        self.counts: Counter[str] = Counter()  # ok, failed, refused, busy, limited, fetched, killed
        self.limiter = RateLimiter(rate_limit, rate_burst)
        self._cache: OrderedDict[str, bytes] = OrderedDict()  # digest -> checked bundle
        self._failed: OrderedDict[str, tuple[float, str]] = OrderedDict()  # digest -> (when, why) of a failed fetch
        self.retry_fetch = 5.0  # seconds before fetching again a digest nobody served
        self._lock = threading.Lock()  # cache and counts (callbacks and workers)
        self._fetch_lock = threading.Lock()  # one fetch at a time; waiters then hit the cache
        self._slots = threading.BoundedSemaphore(max_pending)  # queued + running requests
        # A client may hold at most half of them, so another one always finds room (issue 14).
        self.client_pending = max(1, max_pending // 2)
        self._pending: Counter[str] = Counter()  # client -> admitted requests not answered yet
        self._workers = [Worker(self.instance_id, memory_mb=memory_mb, cache_size=cache_size) for _ in range(workers)]
        self._idle: queue.SimpleQueue[Worker] = queue.SimpleQueue()
        for w in self._workers:
            w.wait_ready()  # announce nothing before the workers can answer
            self._idle.put(w)
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix=f"predictor-{instance_id}")
        self._closed = False
        self._working: set[zenoh.Query] = set()  # admitted on the instance key, not answered yet
        self._heartbeat = threading.Thread(target=self._beat, name=f"predictor-{instance_id}-heartbeat", daemon=True)
        self._heartbeat.start()
        self._queryable = session.declare_queryable(keys.predict("*", "*"), self._on_query, complete=True)
        self._own = session.declare_queryable(keys.predict_instance("*", "*", instance_id), self._on_query,
                                              complete=True)
        self._token = session.liveliness().declare_token(keys.alive(keys.ANY_SYSTEM, "predictor", instance_id))
        log.info("predictor %s serving %s and %s (%s requests/s per client)", instance_id, keys.predict("*", "*"),
                 keys.predict_instance("*", "*", instance_id), f"{rate_limit:g}" if rate_limit > 0 else "no limit:")

    # -- Zenoh thread -----------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        """Decode and admit a query; answer at once when it is bad or the pool is full."""
        try:
            key = str(query.key_expr)
            client = keys.client_of(key)
            if client is None:
                with query:
                    self._count("failed")
                    query.reply_err(f"key '{key}': the client chunk must be a name (skinet/<system>/predict/<client>)")
                return
            why = self.limiter.take(client)
            if why != OK:  # before anything else: a refusal must stay cheap
                with query:
                    system = key.split("/")[1] if "*" not in key.split("/")[1] else keys.ANY_SYSTEM
                    self._reply(query, self._failure(system, "", 0, self.limiter.refusal(client, why)), "limited")
                return
            request = self._decode(query, key)
            if isinstance(request, PredictReply):
                with query:
                    self._reply(query, request, "refused")
                return
            reason = "busy: too many pending requests"
            if not self._admit(client):
                reason = f"busy: client '{client}' has its share of pending requests ({self.client_pending})"
            elif self._slots.acquire(blocking=False):
                if _own_key(key):  # the instance key: "working" replies until the answer
                    self._working_on(query)
                try:
                    self._pool.submit(self._serve, query, request, client)
                    return
                except RuntimeError:  # close() shut the pool down while this query was arriving
                    self._slots.release()
                    self._done_with(query)
                    reason = "predictor shutting down"
                self._release(client)
            else:
                self._release(client)
            with query:
                self._reply(query, self._failure(request.system, request.digest, request.seq, reason), "busy")
        except Exception:  # never let an exception escape into Zenoh
            log.exception("predictor %s: query callback failed", self.instance_id)
            try:
                query.drop()  # finalize now rather than at the caller's timeout
            except Exception:
                pass  # already dropped

    def _decode(self, query: zenoh.Query, key: str) -> PredictRequest | PredictReply:
        """The request, or the failure reply to send for it."""
        system = key.split("/")[1] if "*" not in key.split("/")[1] else keys.ANY_SYSTEM
        if query.payload is None:
            return self._failure(system, "", 0, "empty payload")
        size = len(query.payload)
        if size > self.max_request:  # before anything is copied or decoded
            return self._failure(system, "", 0, f"request of {size} bytes exceeds the limit of {self.max_request}")
        try:
            request = decode(query.payload.to_bytes(), PredictRequest)
        except DecodeError as exc:
            return self._failure(system, "", 0, str(exc))
        try:
            keys.check_chunk(request.system, "system")
            keys.check_chunk(request.digest, "digest")
        except ValueError as exc:
            return self._failure(system, "", request.seq, str(exc))
        if not zenoh.KeyExpr(key).intersects(zenoh.KeyExpr(self._reply_key(key, request.system))):
            mismatch = f"system '{request.system}' does not match key '{key}'"
            return self._failure(system, request.digest, request.seq, mismatch)
        return request

    # -- worker threads ---------------------------------------------------------------

    def _admit(self, client: str) -> bool:
        """Count one more pending request of ``client``, unless it holds its share already."""
        with self._lock:
            if self._pending[client] >= self.client_pending:
                return False
            self._pending[client] += 1
            return True

    def _release(self, client: str) -> None:
        with self._lock:
            self._pending[client] -= 1
            if self._pending[client] <= 0:
                del self._pending[client]  # bounded by the admitted requests, not by the clients seen

    def _serve(self, query: zenoh.Query, request: PredictRequest, client: str) -> None:
        with query:
            try:
                reply = self.answer(request)
                self._done_with(query)
                self._reply(query, reply)
            except Exception:
                log.exception("predictor %s: request %s failed", self.instance_id, request.seq)
            finally:
                self._done_with(query)
                self._slots.release()
                self._release(client)

    # -- heartbeats on the instance key --------------------------------------------------

    def _working_on(self, query: zenoh.Query) -> None:
        """Admitted: say so at once, then every HEARTBEAT seconds until :meth:`_done_with`."""
        with self._lock:
            self._working.add(query)
            self._say_working(query)

    def _done_with(self, query: zenoh.Query) -> None:
        with self._lock:
            self._working.discard(query)

    def _beat(self) -> None:
        while not self._closed:
            time.sleep(HEARTBEAT)
            with self._lock:  # held while replying: _done_with waits, so no reply after the answer
                for query in self._working:
                    self._say_working(query)

    @staticmethod
    def _say_working(query: zenoh.Query) -> None:
        try:
            query.reply(query.key_expr, b"", express=True)
        except zenoh.ZError:
            pass  # the caller gave up (timeout, cancelled)

    def answer(self, request: PredictRequest) -> PredictReply:
        """Compute the reply to one request (docs/semantics.md §6) in a worker process; failures become ``ok=False``."""
        try:
            model = self._bundle(request.system, request.digest)
            worker = self._idle.get()
            try:
                payload = worker.run(request.digest, model, encode(request), min(request.budget, self.max_budget),
                                     self.grace, self.memory_limit)
            finally:
                self._idle.put(worker)
            return decode(payload, PredictReply)
        except (FetchError, WorkerError, DecodeError) as exc:
            if isinstance(exc, WorkerError) and "worker" in str(exc):
                with self._lock:
                    self.counts["killed"] += 1
            return self._failure(request.system, request.digest, request.seq, str(exc))

    def _bundle(self, name: str, digest: str) -> bytes:
        """The checked bundle of ``digest``, from the cache or fetched from its monitor."""
        with self._lock:
            if digest in self._cache:
                self._cache.move_to_end(digest)
                return self._cache[digest]
        with self._fetch_lock:
            with self._lock:
                if digest in self._cache:
                    return self._cache[digest]
                failed = self._failed.get(digest)
                if failed is not None and time.monotonic() - failed[0] < self.retry_fetch:
                    raise FetchError(failed[1])  # a flood of unknown digests costs one fetch each per period
            try:
                model = self._fetch(name, digest)
            except FetchError as exc:
                if exc.unknown:  # not a slow or broken server, which may recover at once
                    with self._lock:
                        self._failed[digest] = (time.monotonic(), str(exc))
                        while len(self._failed) > 256:
                            self._failed.popitem(last=False)
                raise
            with self._lock:
                self._cache[digest] = model
                while len(self._cache) > self.cache_size:
                    self._cache.popitem(last=False)
                self.counts["fetched"] += 1
            return model

    def _fetch(self, name: str, digest: str) -> bytes:
        """Query ``skinet/<system>/model/<digest>``; the first bundle that hashes to ``digest`` wins.

        The hash is checked on the bundle's text before anything is parsed or built.
        """
        key = keys.model(name, digest)  # both checked by _decode
        problems: list[str] = []
        for reply in self.session.get(key, timeout=self.fetch_timeout):
            if reply.ok is None:
                problems.append(f"error reply: {reply.err.payload.to_string()}")
                continue
            payload = reply.ok.payload.to_bytes()
            if len(payload) > self.max_bundle:
                problems.append(f"bundle of {len(payload)} bytes exceeds the limit of {self.max_bundle}")
                continue
            try:
                model = decode(payload, ModelBundle)
            except DecodeError as exc:
                problems.append(str(exc))
                continue
            got = bundle_digest(model)
            if got == digest and model.system == name:
                log.info("predictor %s: fetched model %s", self.instance_id, key)
                return payload
            problems.append(f"bundle hashes to {got}" if model.system == name else
                            f"bundle of system '{model.system}'")
        reasons = "; ".join(dict.fromkeys(problems))  # a frozen server can yield 'Timeout' twice
        raise FetchError(f"cannot fetch model {key}: {reasons or 'no reply'}", unknown=not problems)

    # -- replies ----------------------------------------------------------------------

    def _failure(self, system: str, digest: str, seq: int, error: str) -> PredictReply:
        return PredictReply(system=system, digest=digest, seq=seq, ok=False, error=_one_line(error),
                            instance=self.instance_id)

    def _count(self, kind: str) -> None:
        with self._lock:
            self.counts[kind] += 1

    def _reply(self, query: zenoh.Query, reply: PredictReply, failure: str = "failed") -> None:
        kind = "ok" if reply.ok else failure
        self._count(kind)
        n = self.counts[kind]
        flood = kind in ("limited", "refused")  # cheap for a client to send by the thousand: a few lines
        if not reply.ok and (not flood or n in (1, 10, 100) or n % 1000 == 0):
            log.warning("predictor %s: %s request %s/%s%s: %s", self.instance_id, kind, reply.system, reply.seq,
                        f" (#{n})" if flood else "", reply.error)
        key = self._reply_key(str(query.key_expr), reply.system)
        # A reply travels with its query's congestion control (Zenoh 1.10 ignores one given
        # here): the monitor asks instance keys with DROP (schemas/README.md).
        try:
            query.reply(key, encode(reply), express=True)
        except zenoh.ZError as exc:  # the session closed under us, or a key the query does not accept
            log.warning("predictor %s: cannot reply to %s: %s", self.instance_id, query.key_expr, exc)

    def _reply_key(self, query_key: str, system: str) -> str:
        """Replies go to the key that was queried: the client's shared one or this instance's."""
        client = keys.client_of(query_key) or keys.LOCAL_CLIENT
        if _own_key(query_key):
            return keys.predict_instance(system, client, self.instance_id)
        return keys.predict(system, client)

    def close(self) -> None:
        """Stop serving: withdraw the token and the queryable, then answer the queued work.

        The session stays open (it may be shared); a standalone instance closes it
        afterwards, so no admitted query is lost.
        """
        if self._closed:
            return
        self._closed = True
        undeclare(self._token, self._queryable, self._own)
        for w in self._workers:
            w.close()  # queued and running requests are answered with a one-line failure at once
        self._pool.shutdown(wait=True)
        log.info("predictor %s stopped (%s)", self.instance_id, dict(self.counts))


def _own_key(key: str) -> bool:
    """``skinet/<system>/predict/<client>/<instance>``, not the shared ``.../predict/<client>``."""
    return key.count("/") == 4


def start_predictor(
    session: zenoh.Session,
    instance_id: str,
    *,
    workers: int = 2,
    max_pending: int = 8,
    cache_size: int = 4,
    fetch_timeout: float = 2.0,
    max_budget: float = 10.0,
    memory_limit: int = DEFAULT_MEMORY_LIMIT,
    memory_mb: int = 2048,
    grace: float = 1.0,
    max_request: int = MAX_PREDICT_REQUEST,
    rate_limit: float = RATE_LIMIT,
    rate_burst: float | None = None,
) -> Predictor:
    """Serve predictions on ``session`` (shared or own); returns a handle with ``.close()``.

    Args:
        workers: worker processes computing forecasts (one thread each here).
        max_pending: requests queued or running before answering ``busy``.
        cache_size: systems kept (least recently used dropped first).
        fetch_timeout: seconds to wait for a model bundle.
        max_budget: cap on a request's exploration budget, seconds.
        memory_limit: peak memory the core may use, bytes, shared by the workers (docs/semantics.md §6.1);
            beyond it answers are truncated.
        memory_mb: address-space limit of each worker process, MB (killed beyond it).
        grace: seconds past a request's budget before its worker is killed.
        max_request: largest request payload decoded, bytes; a larger one is refused unread.
        rate_limit: requests per second per client (the key's client chunk), 0: no limit;
            beyond it a request is answered ``rate limited`` at once.
        rate_burst: requests a client may send at once (default: one second's worth).
    """
    return Predictor(session, instance_id, workers=workers, max_pending=max_pending,
                     cache_size=cache_size, fetch_timeout=fetch_timeout, max_budget=max_budget,
                     memory_limit=memory_limit, memory_mb=memory_mb, grace=grace, max_request=max_request,
                     rate_limit=rate_limit, rate_burst=rate_burst)
