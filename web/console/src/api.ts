// The console's client of tpr-web's /api/v1 (web/api.h). JSON is the
// proto's own mapping: lowerCamelCase names, 64-bit integers as strings.
// Every failure becomes an ApiError carrying the gRPC code name, so that
// the screens can say what went wrong.

export interface ApiErrorBody {
  code: string;
  message: string;
  requestId?: string;
}

export class ApiError extends Error {
  constructor(
    readonly code: string,
    message: string,
    readonly httpStatus: number,
  ) {
    super(message);
  }
}

export interface Neighbor {
  rank: number;
  id: string;
  label: string;
  distance: number;
}

export interface SearchStats {
  emdComputations: string;
  lowerBounds: string;
  nodesVisited: string;
  milliseconds: number;
}

export interface Feature {
  kind: string;
  weight: number;
  integralGeodesic: number;
}

export interface Signature {
  features: Feature[];
  mesh?: { vertices: string; faces: string; area: number; genus: string; components: string; boundaryEdges: string };
  extractorVersion?: string;
  spectrum?: number[];
  signatureVersion?: number;
}

export interface FeatureVertices {
  vertices: number[];
  positions: number[];
}

export interface ExtractResponse {
  signature: Signature;
  warnings: string[];
  explanation?: { vertexRegion: number[]; featureVertices: FeatureVertices[] };
  media?: { thumbnailPng: string; previewPly: string };
}

export interface SearchReply {
  query?: ExtractResponse;
  neighbors: Neighbor[];
  stats: SearchStats;
}

export interface Model {
  id: string;
  label: string;
  signature?: Signature;
  addedUnixMicros?: string;
}

export interface ListReply {
  models: Model[];
  nextPageToken: string;
}

export interface StatsReply {
  models: string;
  labels: Record<string, string>;
  indexed: string;
  buffered: string;
  diskBytes: string;
  memoryBytes: string;
  shards: { shard: number; address: string; stats: StatsReply }[];
}

export interface ServiceState {
  address: string;
  ready: boolean;
  reason: string;
}

export interface StatusReply {
  extractor: ServiceState;
  indexer: ServiceState;
  stats: StatsReply | null;
  statsError?: ApiErrorBody;
  searches: {
    total: number;
    inWindow: number;
    windowSeconds: number;
    perSecond: number;
    p50Ms: number;
    p95Ms: number;
    indexerP50Ms: number;
    indexerP95Ms: number;
  };
}

export interface SearchOptions {
  k: number;
  label: string;
  intent: string;
  excludeSelf?: boolean;
}

const KEY_STORAGE = 'tpr-api-key';

export function apiKey(): string {
  return sessionStorage.getItem(KEY_STORAGE) ?? '';
}

export function setApiKey(key: string): void {
  if (key) sessionStorage.setItem(KEY_STORAGE, key);
  else sessionStorage.removeItem(KEY_STORAGE);
}

function headers(): HeadersInit {
  const key = apiKey();
  return key ? { Authorization: `Bearer ${key}` } : {};
}

async function request(path: string, init: RequestInit = {}): Promise<Response> {
  let response: Response;
  try {
    response = await fetch(path, { ...init, headers: { ...headers(), ...(init.headers ?? {}) } });
  } catch {
    throw new ApiError('UNAVAILABLE', 'tpr-web does not answer: is it running, and is this its address?', 0);
  }
  if (response.ok) return response;
  let body: ApiErrorBody = { code: 'UNKNOWN', message: `HTTP ${response.status}` };
  try {
    body = (await response.json()) as ApiErrorBody;
  } catch {
    // A proxy's HTML page: keep the HTTP status.
  }
  throw new ApiError(body.code, body.message, response.status);
}

async function json<T>(path: string, init: RequestInit = {}): Promise<T> {
  return (await (await request(path, init)).json()) as T;
}

function searchParams(options: SearchOptions): URLSearchParams {
  const p = new URLSearchParams({ k: String(options.k) });
  if (options.label) p.set('label', options.label);
  if (options.intent) p.set('intent', options.intent);
  if (options.excludeSelf) p.set('exclude_self', '1');
  return p;
}

export function searchById(id: string, options: SearchOptions): Promise<SearchReply> {
  const p = searchParams(options);
  p.set('id', id);
  return json<SearchReply>(`/api/v1/search?${p}`);
}

export function searchByUpload(file: File, options: SearchOptions): Promise<SearchReply> {
  const form = new FormData();
  form.append('mesh', file, file.name);
  const p = searchParams(options);
  p.set('explain', '1');
  return json<SearchReply>(`/api/v1/search?${p}`, { method: 'POST', body: form });
}

export function getModel(id: string): Promise<Model> {
  return json<Model>(`/api/v1/models/${encodeURIComponent(id)}`);
}

export function listModels(label: string, pageSize: number, pageToken: string): Promise<ListReply> {
  const p = new URLSearchParams({ page_size: String(pageSize) });
  if (label) p.set('label', label);
  if (pageToken) p.set('page_token', pageToken);
  return json<ListReply>(`/api/v1/models?${p}`);
}

export function stats(): Promise<StatsReply> {
  return json<StatsReply>('/api/v1/stats');
}

export function status(): Promise<StatusReply> {
  return json<StatusReply>('/api/v1/status');
}

// thumbnailUrl fetches a thumbnail with the API key and returns an object
// URL for an <img>; NOT_FOUND (no media) comes back as an ApiError.
export async function thumbnailUrl(id: string): Promise<string> {
  const response = await request(`/api/v1/thumbnails/${encodeURIComponent(id)}`);
  return URL.createObjectURL(await response.blob());
}

export async function preview(id: string): Promise<ArrayBuffer> {
  const response = await request(`/api/v1/previews/${encodeURIComponent(id)}`);
  return response.arrayBuffer();
}

// describe turns an error into a sentence for a person.
export function describe(error: unknown, doing: string): string {
  if (!(error instanceof ApiError)) return `${doing} failed: ${String(error)}`;
  switch (error.code) {
    case 'UNAUTHENTICATED':
      return `${doing} needs an API key: enter one under "API key" (${error.message}).`;
    case 'PERMISSION_DENIED':
      return `${doing}: this API key's role is too low (${error.message}).`;
    case 'UNAVAILABLE':
      return `${doing}: a service is down or unreachable (${error.message}).`;
    case 'INVALID_ARGUMENT':
      return `${doing}: refused (${error.message}).`;
    case 'RESOURCE_EXHAUSTED':
      return `${doing}: too large or the service is busy (${error.message}).`;
    case 'NOT_FOUND':
      return `${doing}: not found (${error.message}).`;
    case 'UNIMPLEMENTED':
      return `${doing}: the service does not offer this (${error.message}).`;
    case 'DEADLINE_EXCEEDED':
      return `${doing}: the service took too long (${error.message}).`;
    default:
      return `${doing} failed: ${error.code}: ${error.message}`;
  }
}
