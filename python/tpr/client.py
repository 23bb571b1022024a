"""The typed Python client of TPR Search over tpr-extractor and tpr-indexer.

A thin layer over the generated gRPC stubs (``tpr.v1``): meshes are uploaded
in 1 MiB chunks, searches are iterators over the server's stream, every call
has a deadline, and every failure is a :class:`TprError` with the gRPC code.
Ids and labels given by :meth:`Client.add` follow the ``tpr add`` rule: a
mesh directly in the folder given gets ``FOLDER/FILE`` and the folder's
name as label, a mesh in a subfolder its path below the folder given and
the subfolder's name.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from typing import Dict, Iterator, List, Optional, Tuple

import grpc

from tpr.v1 import extractor_pb2, extractor_pb2_grpc, indexer_pb2, indexer_pb2_grpc

CHUNK_BYTES = 1 << 20
MESH_EXTENSIONS = (".off", ".obj", ".ply", ".stl")
_INTENTS = {
    "balanced": indexer_pb2.INTENT_BALANCED,
    "identity": indexer_pb2.INTENT_IDENTITY,
    "kind": indexer_pb2.INTENT_KIND,
}


class TprError(Exception):
    """A failed call: ``code`` is the grpc.StatusCode, ``message`` the
    server's (or the client's) explanation."""

    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(f"{code.name}: {message}")
        self.code = code
        self.message = message


@dataclasses.dataclass(frozen=True)
class Neighbor:
    """One search result: 1-based rank, id, label and distance (0 for the
    same shape; see docs/distances.md for the scale)."""

    rank: int
    id: str
    label: str
    distance: float


def collect_files(path: str, label: Optional[str] = None) -> List[Tuple[str, str, str]]:
    """(path, id, label) of every mesh under a folder (recursive, sorted) or
    of one mesh file, named as ``tpr add`` names them; ``label`` replaces
    every label. Raises TprError(NOT_FOUND) for a path that does not exist
    and TprError(INVALID_ARGUMENT) for two files with one id."""
    if os.path.isdir(path):
        folder = os.path.basename(os.path.normpath(os.path.abspath(path)))
        found = []
        for root, dirs, files in os.walk(path):
            dirs.sort()
            for name in sorted(files):
                if name.lower().endswith(MESH_EXTENSIONS):
                    full = os.path.join(root, name)
                    rel = os.path.relpath(full, path).replace(os.sep, "/")
                    if "/" in rel:
                        found.append((full, rel, rel.split("/")[-2]))
                    else:
                        found.append((full, f"{folder}/{rel}", folder))
    elif os.path.isfile(path):
        parent = os.path.basename(os.path.dirname(os.path.abspath(path)))
        found = [(path, f"{parent}/{os.path.basename(path)}", parent)]
    else:
        raise TprError(grpc.StatusCode.NOT_FOUND, f"{path} is neither a file nor a folder")
    seen: Dict[str, str] = {}
    for full, model_id, _ in found:
        if model_id in seen:
            raise TprError(
                grpc.StatusCode.INVALID_ARGUMENT,
                f"files {seen[model_id]} and {full} would both get the id {model_id}",
            )
        seen[model_id] = full
    return [(p, i, label if label is not None else l) for p, i, l in found]


class Client:
    """Both services. Thread-safe (gRPC channels are); use as a context
    manager or call close().

    extractor, indexer: "HOST:PORT" of tpr-extractor and of tpr-indexer (or
    tpr-gateway). api_key: sent as "authorization: Bearer KEY" (default:
    the TPR_API_KEY environment variable). tls: speak TLS; tls_ca: PEM file
    of the authority to trust (default: the system's). timeout: seconds per
    call.
    """

    def __init__(
        self,
        extractor: str = "127.0.0.1:7001",
        indexer: str = "127.0.0.1:7002",
        api_key: Optional[str] = None,
        tls: bool = False,
        tls_ca: Optional[str] = None,
        timeout: float = 60.0,
    ):
        self._extractor_address = extractor
        self._indexer_address = indexer
        key = api_key if api_key is not None else os.environ.get("TPR_API_KEY", "")
        self._metadata = (("authorization", f"Bearer {key}"),) if key else ()
        self._timeout = timeout
        options = [("grpc.max_receive_message_length", 64 << 20)]
        if tls:
            root = open(tls_ca, "rb").read() if tls_ca else None
            credentials = grpc.ssl_channel_credentials(root_certificates=root)
            self._extractor_channel = grpc.secure_channel(extractor, credentials, options)
            self._indexer_channel = grpc.secure_channel(indexer, credentials, options)
        else:
            self._extractor_channel = grpc.insecure_channel(extractor, options)
            self._indexer_channel = grpc.insecure_channel(indexer, options)
        self._extractor = extractor_pb2_grpc.ExtractorStub(self._extractor_channel)
        self._indexer = indexer_pb2_grpc.IndexerStub(self._indexer_channel)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Closes both channels."""
        self._extractor_channel.close()
        self._indexer_channel.close()

    def _error(self, e: grpc.RpcError, service: str, address: str) -> TprError:
        code, details = e.code(), e.details() or ""
        if code == grpc.StatusCode.UNAVAILABLE:
            details = f"cannot reach {service} at {address}: {details}"
        elif code == grpc.StatusCode.UNIMPLEMENTED and not details:
            details = f"the server at {address} is not a {service}"
        return TprError(code, details)

    def _indexer_call(self, method, request):
        try:
            return method(request, timeout=self._timeout, metadata=self._metadata)
        except grpc.RpcError as e:
            raise self._error(e, "tpr-indexer", self._indexer_address) from None

    def extract(self, path: str) -> extractor_pb2.ExtractResponse:
        """The signature (and timings) of the mesh file at ``path``."""
        try:
            data = open(path, "rb").read()
        except OSError as e:
            raise TprError(grpc.StatusCode.NOT_FOUND, f"cannot read {path}: {e.strerror}") from None

        def chunks():
            for start in range(0, max(len(data), 1), CHUNK_BYTES):
                request = extractor_pb2.ExtractRequest(data=data[start : start + CHUNK_BYTES])
                if start == 0:
                    request.file_name = os.path.basename(path)
                yield request

        try:
            return self._extractor.Extract(chunks(), timeout=self._timeout, metadata=self._metadata)
        except grpc.RpcError as e:
            raise self._error(e, "tpr-extractor", self._extractor_address) from None

    def add(
        self, path_or_folder: str, label: Optional[str] = None, update: bool = False
    ) -> List[str]:
        """Indexes a mesh file or every mesh of a folder (see the module's
        naming rule; ``label`` replaces the labels) and returns the ids
        added or replaced. Ids already present are skipped unless
        ``update``. Stops at the first failure, raising its TprError."""
        done = []
        for path, model_id, model_label in collect_files(path_or_folder, label):
            bytes_ = open(path, "rb").read()
            response = self.extract(path)
            model = indexer_pb2.Model(id=model_id, label=model_label, signature=response.signature)
            model.metadata["file_name"] = os.path.basename(path)
            model.metadata["sha256"] = hashlib.sha256(bytes_).hexdigest()
            try:
                self._indexer_call(
                    self._indexer.Upsert, indexer_pb2.UpsertRequest(model=model, overwrite=update)
                )
            except TprError as e:
                if e.code == grpc.StatusCode.ALREADY_EXISTS:
                    continue
                raise
            done.append(model_id)
        return done

    def search(
        self,
        mesh_or_id: str,
        k: int = 10,
        intent: str = "balanced",
        label: Optional[str] = None,
        radius: float = 0.0,
    ) -> Iterator[Neighbor]:
        """The k nearest models as an iterator over the server's stream, in
        ascending distance; stop iterating to cancel. ``mesh_or_id``: a mesh
        file (extracted first) or a stored id. ``intent``: "balanced",
        "identity" (this model in any pose) or "kind" (models of this kind).
        """
        if intent not in _INTENTS:
            raise TprError(grpc.StatusCode.INVALID_ARGUMENT, f"intent must be one of {sorted(_INTENTS)}")
        request = indexer_pb2.SearchRequest(k=k, radius=radius, label=label or "", intent=_INTENTS[intent])
        if os.path.isfile(mesh_or_id):
            request.signature.CopyFrom(self.extract(mesh_or_id).signature)
        else:
            request.id = mesh_or_id
        stream = self._indexer.Search(request, timeout=self._timeout, metadata=self._metadata)
        try:
            for response in stream:
                if response.HasField("neighbor"):
                    n = response.neighbor
                    yield Neighbor(n.rank, n.id, n.label, n.distance)
        except grpc.RpcError as e:
            raise self._error(e, "tpr-indexer", self._indexer_address) from None
        finally:
            stream.cancel()

    def query(self, mesh_or_id: str, k: int = 10, intent: str = "balanced",
              label: Optional[str] = None, radius: float = 0.0) -> List[Neighbor]:
        """search() as a list."""
        return list(self.search(mesh_or_id, k=k, intent=intent, label=label, radius=radius))

    def get(self, model_id: str) -> indexer_pb2.Model:
        """The stored model ``model_id`` with its signature
        (TprError NOT_FOUND when unknown)."""
        return self._indexer_call(self._indexer.Get, indexer_pb2.GetRequest(id=model_id))

    def remove(self, model_id: str) -> None:
        """Deletes ``model_id`` (TprError NOT_FOUND when unknown)."""
        self._indexer_call(self._indexer.Delete, indexer_pb2.DeleteRequest(id=model_id))

    def list(self, label: Optional[str] = None) -> Iterator[indexer_pb2.Model]:
        """Every stored model (with ``label`` if given) in id order, without
        signatures, fetched a page at a time."""
        token = ""
        while True:
            page = self._indexer_call(
                self._indexer.List,
                indexer_pb2.ListRequest(page_size=1000, page_token=token, label=label or ""),
            )
            yield from page.models
            token = page.next_page_token
            if not token:
                return

    def stats(self) -> indexer_pb2.StatsResponse:
        """Counts and sizes: ``models``, ``labels`` (label -> count),
        ``disk_bytes``, ..."""
        return self._indexer_call(self._indexer.Stats, indexer_pb2.StatsRequest())
