import { z } from 'zod/mini';
import { LinkError } from '../../fleet/errors';
import { HttpClient, preview, uploadWithProgress, type RawResponse } from '../../fleet/http';
import type { RrfClient, UploadOptions } from './rrf-client';
import { connectAnswer, connectRefusal, isStandaloneAnswer } from './rrf-connect';
import {
  directoryListing,
  objectModelSchema,
  parsedFileInfoSchema,
  type DirEntry,
  type ObjectModel,
  type ParsedFileInfo,
} from './wire';
import { fromGateway, gatewayBodyError } from '../../fleet/faults';

/**
 * Typed client of the DSF REST API (`duet-dsf-rest-api.txt`), one method per endpoint, on the
 * console's `HttpClient` (`/machines/<id>/machine/...`).
 *
 * Through the gateway there is no session key: the gateway holds the DSF session (it connects,
 * keeps the key and adds it on the way out; `src/controllers/duet/gateway.ts`) and answers
 * `connect` without `sessionKey`. Only where a simulator answers in the page (msw, in tests) does
 * `connect` give a key, which is then sent as `X-Session-Key` and on the socket URL.
 *
 * File paths are whole RRF paths ("0:/gcodes/a b.gcode") and go into the URL as ONE
 * percent-encoded segment, as Duet Web Control does (`encodeURIComponent(filename)`).
 */

/**
 * DSF answers errors as plain text (an exception message) or nothing. The console server's own
 * failure (`{"error","gateway":true}`: it could not reach the Duet) is never read as DSF's: its 502
 * is not "Incompatible DCS version", its 401/403 not a session that expired.
 */
export function parseDuetError(status: number, body: unknown, text: string): LinkError | null {
  if (status < 400) return null;
  const own = gatewayBodyError(status, body);
  if (own) return own;
  const message = text.trim();
  if (status === 401 || status === 403) {
    return new LinkError(
      'http',
      `HTTP ${status}: session expired or password wrong${message ? ` (${preview(message)})` : ''}`,
      {
        status,
      },
    );
  }
  // The gateway's answer for a standalone board with no free session (`rr_connect` err 2).
  if (status === 503 && typeof body === 'object' && body !== null && (body as { err?: unknown }).err === 2)
    return connectRefusal(2);
  if (status === 502)
    return new LinkError('vendor', 'Incompatible DCS version (502)', {
      status,
      vendorMessage: message || null,
    });
  if (status === 503)
    return new LinkError('vendor', 'DCS is unavailable (503): the Duet service is down', {
      status,
      vendorMessage: message || null,
    });
  if (message)
    return new LinkError('vendor', `HTTP ${status}: ${preview(message, 200)}`, {
      status,
      vendorMessage: message,
    });
  return null;
}

/** DSF itself refused the session (401/403); the console server's own refusal is not DSF's. */
export function isAuthError(e: unknown): boolean {
  return e instanceof LinkError && (e.status === 401 || e.status === 403) && !fromGateway(e);
}

export function encodePath(path: string): string {
  return encodeURIComponent(path);
}

export interface CodeOptions {
  async?: boolean;
  commandId?: string;
  timeoutMs?: number;
}

export type DuetApi = 'dsf' | 'standalone';

export class DuetClient {
  readonly http: HttpClient;
  /** Only when no gateway holds the session (msw); null through the gateway. */
  sessionKey: string | null = null;
  /** `connect` succeeded and no 401/403 said the session is gone since. */
  connected = false;
  /**
   * Which API the Duet speaks, learned by `connect`: 'standalone' (RepRapFirmware without an SBC,
   * `rr_*`) sends every request through `rrf`.
   */
  api: DuetApi = 'dsf';
  /** A reply of a standalone board nobody waited for (a message): the session logs it. */
  onReply: (text: string) => void = () => undefined;
  private rrfClient: RrfClient | null = null;

  constructor(machineId: string) {
    this.http = new HttpClient({
      machineId,
      timeoutMs: 10_000,
      parseError: parseDuetError,
      headers: (): Record<string, string> => (this.sessionKey ? { 'X-Session-Key': this.sessionKey } : {}),
    });
  }

  /** The standalone API (loaded with the first standalone answer: DSF pages do not carry it). */
  get rrf(): RrfClient {
    if (!this.rrfClient) throw new Error('not a standalone Duet (rr_* not loaded)');
    return this.rrfClient;
  }

  private async loadRrf(): Promise<RrfClient> {
    if (!this.rrfClient) {
      const { RrfClient } = await import('./rrf-client');
      this.rrfClient ??= new RrfClient(this.http, () => this.sessionKey);
      this.rrfClient.onReply = (text) => this.onReply(text);
    }
    return this.rrfClient;
  }

  get standalone(): boolean {
    return this.api === 'standalone';
  }

  /**
   * `GET /machine/connect?password=` — the gateway answers it from its own session (a configured
   * password wins; a typed one is checked with the Duet and kept by the gateway), without a key.
   * The gateway probed the board (`gateway.ts`): a standalone board's answer is `rr_connect`'s,
   * with a numeric `err`, which DSF's never has. Where no gateway answers (msw) and DSF's connect
   * is not there (404, or the board's web page), `rr_connect` is asked directly.
   */
  async connect(password?: string, signal?: AbortSignal): Promise<string | null> {
    this.connected = false;
    let r: z.infer<typeof connectAnswer>;
    try {
      r = await this.http.json({ path: '/machine/connect', query: { password }, signal }, connectAnswer);
    } catch (e) {
      // No DSF there: a 404, or a standalone board's web page (HTML, 200), never from a gateway.
      const notDsf = e instanceof LinkError && (e.status === 404 || e.kind === 'protocol');
      if (!notDsf || fromGateway(e)) throw e;
      this.sessionKey = await (await this.loadRrf()).connect(password, signal);
      this.api = 'standalone';
      this.connected = true;
      return this.sessionKey;
    }
    const standalone = isStandaloneAnswer(r);
    if (standalone) {
      const refused = connectRefusal(r.err ?? 0);
      if (refused) throw refused;
      (await this.loadRrf()).reset();
    }
    this.api = standalone ? 'standalone' : 'dsf';
    this.sessionKey = r.sessionKey === undefined || r.sessionKey === null ? null : String(r.sessionKey);
    this.connected = true;
    return this.sessionKey;
  }

  /** A poll asked for at once (a code waits for its reply, fetched by the next poll). */
  kick: () => void = () => undefined;

  /** Plugins are DSF's (an SBC): a standalone board has none. */
  private noPlugins(): void {
    if (this.standalone)
      throw new LinkError('vendor', 'Plugins need DSF (a Duet with an SBC): this board runs standalone');
  }

  /** The session is known to be gone (401/403): the next `connect` gets a new one. */
  forget(): void {
    this.sessionKey = null;
    this.connected = false;
  }

  async noop(signal?: AbortSignal): Promise<void> {
    if (this.standalone) return this.rrf.noop(signal);
    await this.http.raw({ path: '/machine/noop', timeoutMs: 5000, signal });
  }

  async disconnect(): Promise<void> {
    try {
      if (this.standalone) await this.rrf.disconnect();
      else await this.http.raw({ path: '/machine/disconnect', timeoutMs: 3000 });
    } finally {
      this.forget();
    }
  }

  /** Socket URL (same origin); with the session key only when there is one (msw). */
  socketUrl(): string {
    return this.http.url('/machine', { sessionKey: this.sessionKey ?? undefined });
  }

  /**
   * `GET /machine/model`: the full object model, as raw JSON (the session validates it as it does
   * socket frames). `/machine/model` rather than `/machine/status`: the OpenAPI file says status
   * is "not supported before v3.4.6 or v3.5-b4"; model works on every DSF.
   */
  async modelRaw(signal?: AbortSignal): Promise<Record<string, unknown>> {
    return this.http.json({ path: '/machine/model', signal }, z.record(z.string(), z.unknown()));
  }

  /** `GET /machine/status`: the full object model. */
  status(): Promise<ObjectModel> {
    return this.http.json({ path: '/machine/status' }, objectModelSchema);
  }

  /** `POST /machine/code` — plain-text body; the reply is plain text ("" when there is none). */
  async code(code: string, opts: CodeOptions = {}): Promise<string> {
    if (this.standalone) return this.rrf.code(code, opts, this.kick);
    const r = await this.http.raw({
      method: 'POST',
      path: '/machine/code',
      query: opts.async ? { async: 'true' } : undefined,
      headers: { 'Content-Type': 'text/plain' },
      body: code,
      commandId: opts.commandId,
      // Codes may run long (homing, heating with M116): DSF answers when they are done.
      timeoutMs: opts.timeoutMs ?? (opts.async ? 10_000 : 120_000),
    });
    return r.text;
  }

  async download(path: string, signal?: AbortSignal): Promise<Blob> {
    if (this.standalone) return this.rrf.download(path, signal);
    const r = await this.http.blob({ path: `/machine/file/${encodePath(path)}`, timeoutMs: 60_000, signal });
    return r.blob;
  }

  /** Download as text (height map, macros); non-2xx throws. */
  async readText(path: string, signal?: AbortSignal): Promise<string> {
    if (this.standalone) return this.rrf.readText(path, signal);
    const r = await this.http.raw({ path: `/machine/file/${encodePath(path)}`, timeoutMs: 30_000, signal });
    return r.text;
  }

  fileUrl(path: string): string {
    if (this.standalone) return this.rrf.fileUrl(path);
    return this.http.url(`/machine/file/${encodePath(path)}`);
  }

  /** `PUT /machine/file/{path}?timeModified=<ISO>` with upload progress; 201 when created. */
  upload(path: string, body: Blob | ArrayBuffer | string, opts: UploadOptions = {}): Promise<RawResponse> {
    if (this.standalone) return this.rrf.upload(path, body, opts);
    const headers: Record<string, string> = { 'Content-Type': 'application/octet-stream' };
    if (this.sessionKey) headers['X-Session-Key'] = this.sessionKey;
    if (opts.commandId) headers['X-Shopdeck-Command'] = opts.commandId;
    return uploadWithProgress({
      method: 'PUT',
      url: this.http.url(`/machine/file/${encodePath(path)}`, {
        timeModified: opts.timeModified ? opts.timeModified.toISOString() : undefined,
      }),
      body,
      headers,
      onProgress: opts.onProgress,
      signal: opts.signal,
      timeoutMs: 600_000,
    });
  }

  /** `GET /machine/fileinfo/{path}?readThumbnailContent=true` */
  fileInfo(path: string, thumbnails = true, signal?: AbortSignal): Promise<ParsedFileInfo> {
    if (this.standalone) return this.rrf.fileInfo(path, thumbnails, signal);
    return this.http.json(
      {
        path: `/machine/fileinfo/${encodePath(path)}`,
        query: { readThumbnailContent: thumbnails ? 'true' : undefined },
        signal,
      },
      parsedFileInfoSchema,
    );
  }

  async deleteFile(path: string, opts: { recursive?: boolean; commandId?: string } = {}): Promise<void> {
    if (this.standalone) return this.rrf.deleteFile(path, opts);
    await this.http.raw({
      method: 'DELETE',
      path: `/machine/file/${encodePath(path)}`,
      query: { recursive: opts.recursive ? 'true' : undefined },
      commandId: opts.commandId,
    });
  }

  /** `POST /machine/file/move` as a form. 409: the target exists — ask, then resend with force. */
  async move(from: string, to: string, opts: { force?: boolean; commandId?: string } = {}): Promise<void> {
    if (this.standalone) return this.rrf.move(from, to, opts);
    const form = new URLSearchParams({ from, to });
    if (opts.force) form.set('force', 'true');
    await this.http.raw({
      method: 'POST',
      path: '/machine/file/move',
      headers: { 'Content-Type': 'application/x-www-form-urlencoded' },
      body: form.toString(),
      commandId: opts.commandId,
    });
  }

  listDirectory(dir: string, signal?: AbortSignal): Promise<DirEntry[]> {
    if (this.standalone) return this.rrf.listDirectory(dir, signal);
    return this.http.json({ path: `/machine/directory/${encodePath(dir)}`, signal }, directoryListing);
  }

  async makeDirectory(dir: string, commandId?: string): Promise<void> {
    if (this.standalone) return this.rrf.makeDirectory(dir, commandId);
    await this.http.raw({ method: 'PUT', path: `/machine/directory/${encodePath(dir)}`, commandId });
  }

  async installPlugin(zip: Blob | ArrayBuffer, commandId?: string): Promise<void> {
    this.noPlugins();
    await this.http.raw({
      method: 'PUT',
      path: '/machine/plugin',
      headers: { 'Content-Type': 'application/octet-stream' },
      body: zip,
      commandId,
      timeoutMs: 300_000,
    });
  }

  async uninstallPlugin(name: string, commandId?: string): Promise<void> {
    this.noPlugins();
    await this.http.raw({
      method: 'DELETE',
      path: '/machine/plugin',
      headers: { 'Content-Type': 'text/plain' },
      body: name,
      commandId,
    });
  }

  async startPlugin(name: string, commandId?: string): Promise<void> {
    this.noPlugins();
    await this.http.raw({
      method: 'POST',
      path: '/machine/startPlugin',
      headers: { 'Content-Type': 'text/plain' },
      body: name,
      commandId,
    });
  }

  async stopPlugin(name: string, commandId?: string): Promise<void> {
    this.noPlugins();
    await this.http.raw({
      method: 'POST',
      path: '/machine/stopPlugin',
      headers: { 'Content-Type': 'text/plain' },
      body: name,
      commandId,
    });
  }
}

/** "0:/gcodes/sub/file.gcode" → "file.gcode" */
export function baseName(path: string): string {
  const i = path.lastIndexOf('/');
  return i >= 0 ? path.slice(i + 1) : path;
}

/** Join an RRF directory and a name ("0:/gcodes/" + "a.gcode" → "0:/gcodes/a.gcode"). */
export function joinPath(dir: string, name: string): string {
  return dir.endsWith('/') ? dir + name : `${dir}/${name}`;
}

/** Quote a path for a G-code string parameter (RRF doubles embedded quotes). */
export function quoteGcode(path: string): string {
  return `"${path.replace(/"/g, '""')}"`;
}
