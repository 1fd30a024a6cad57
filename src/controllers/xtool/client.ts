import { LinkError } from '../../fleet/errors';
import type { z } from 'zod/mini';
import {
  HttpClient,
  parseJsonLenient,
  uploadWithProgress,
  type RawResponse,
  type RequestOptions,
  type UploadProgress,
} from '../../fleet/http';
import { gatewayBodyError, isLinkFault } from '../../fleet/faults';
import {
  devNameSchema,
  dotModeSchema,
  laserPowerInfoSchema,
  laserPowerTypeSchema,
  listSchema,
  macSchema,
  machineTypeSchema,
  offsetSchema,
  parseXtoolError,
  peripheryStatusSchema,
  pingSchema,
  progressSchema,
  resultSchema,
  upgradeReplySchema,
  versionSchema,
  workingStaSchema,
} from './wire';

/**
 * Typed client for the xTool D-series HTTP API: one method per endpoint of the document. All
 * requests go through one serialized HttpClient: the laser is an ESP32 that must never see two
 * requests at once. Methods that change the machine take `commandId` (→ X-Shopdeck-Command);
 * reads take the `signal` of the session's run or of the query that asked, so a stop (or a view
 * that went away) cancels them, and one cancelled while waiting in the lane is never sent.
 */

/** Upload targets of POST /upload: filetype 0 → /frame.gcode, 1 → /tmp.gcode, or a full path. */
export type UploadTarget = { kind: 'job' } | { kind: 'frame' } | { kind: 'path'; filename: string };

export function uploadPath(t: UploadTarget): string {
  return t.kind === 'job' ? '/tmp.gcode' : t.kind === 'frame' ? '/frame.gcode' : t.filename;
}

export type SwitchAction = 'setLimitStopSwitch' | 'setTiltStopSwitch' | 'setMovingStopSwitch';
export type ThresholdAction = 'setTiltCheckThreshold' | 'setMovingCheckThreshold';

/** The query parameter each set* action takes (document, "GET /system"). */
export const SYSTEM_PARAM: Record<
  SwitchAction | ThresholdAction | 'setFlameAlarmMode' | 'setFlameAlarmSensitivity',
  string
> = {
  setLimitStopSwitch: 'limitStopSwitch',
  setTiltStopSwitch: 'tiltStopSwitch',
  setMovingStopSwitch: 'movingStopSwitch',
  setTiltCheckThreshold: 'tiltCheckThreshold',
  setMovingCheckThreshold: 'movingCheckThreshold',
  setFlameAlarmMode: 'flameAlarmMode',
  setFlameAlarmSensitivity: 'flameAlarmSensitivity',
};

/**
 * A read's own timeout. Under 2 s latency each way a request takes 8 s: the gateway opens a new
 * TCP connection per request (keep-alive off, sharing.ts), one round trip, then the request's.
 * A silent link is shown long before (the session's liveness window); this only ends the wait.
 */
export const READ_TIMEOUT_MS = 12_000;

export class XtoolClient {
  readonly http: HttpClient;
  /**
   * Called with the time the request took whenever the laser answered (any status, any body that
   * came whole): the session's liveness. A failed request (no answer, the console server's own
   * failure, a 5xx, a cut answer) is not an answer.
   */
  onAnswer: ((ms: number) => void) | null = null;
  /**
   * Called on each progress event of an upload (the bytes go through; the polls wait behind it in
   * the lane; only where there is an XMLHttpRequest, the browser) and when it is answered.
   */
  onTransfer: (() => void) | null = null;
  private readonly now: () => number;

  constructor(machineId: string, opts: { timeoutMs?: number; now?: () => number } = {}) {
    this.now = opts.now ?? Date.now;
    this.http = new HttpClient({
      machineId,
      timeoutMs: opts.timeoutMs ?? READ_TIMEOUT_MS,
      // The console server's own failure body first: its 502 is never the laser's answer.
      parseError: (status, body, text) =>
        gatewayBodyError(status, body) ?? parseXtoolError(status, body, text),
    });
  }

  // --- reads --------------------------------------------------------------------------------

  ping(signal?: AbortSignal) {
    return this.json({ path: '/ping', signal }, pingSchema);
  }
  progress(signal?: AbortSignal) {
    return this.json({ path: '/progress', signal }, progressSchema);
  }
  machineType(signal?: AbortSignal) {
    return this.json({ path: '/getmachinetype', signal }, machineTypeSchema);
  }
  laserPowerType(signal?: AbortSignal) {
    return this.json({ path: '/getlaserpowertype', signal }, laserPowerTypeSchema);
  }
  laserPowerInfo(signal?: AbortSignal) {
    return this.json({ path: '/getlaserpowerinfo', signal }, laserPowerInfoSchema);
  }
  peripheryStatus(signal?: AbortSignal) {
    return this.json({ path: '/peripherystatus', signal }, peripheryStatusSchema);
  }
  mac(signal?: AbortSignal) {
    return this.system('mac', macSchema, signal);
  }
  version(signal?: AbortSignal) {
    return this.system('version', versionSchema, signal);
  }
  workingSta(signal?: AbortSignal) {
    return this.system('get_working_sta', workingStaSchema, signal);
  }
  offset(signal?: AbortSignal) {
    return this.system('offset', offsetSchema, signal);
  }
  dotMode(signal?: AbortSignal) {
    return this.system('dotMode', dotModeSchema, signal);
  }
  deviceName(signal?: AbortSignal) {
    return this.system('get_dev_name', devNameSchema, signal);
  }
  list(dir?: string, signal?: AbortSignal) {
    return this.json({ path: '/list', query: { dir }, signal }, listSchema);
  }

  /**
   * Raw answer of any path, for telling other xTool models apart (never throws on the device's own
   * words; a failed request — no answer, the console server's failure, a 5xx — is thrown).
   */
  async probe(path: string, signal?: AbortSignal): Promise<string> {
    try {
      const r = await this.lane(() => this.http.raw({ path, signal }), signal);
      return `${path} → ${r.status}: ${r.text.trim().slice(0, 300)}`;
    } catch (e) {
      if (e instanceof LinkError && !isLinkFault(e) && (e.kind === 'http' || e.kind === 'vendor'))
        return `${path} → ${e.message}`;
      throw e;
    }
  }

  // --- settings (GET /system?action=set…) -----------------------------------------------------

  setDeviceName(name: string, commandId: string) {
    return this.json({ path: '/system', query: { action: 'set_dev_name', name }, commandId }, resultSchema);
  }

  setSystem(action: keyof typeof SYSTEM_PARAM, value: number, commandId: string) {
    return this.json(
      { path: '/system', query: { action, [SYSTEM_PARAM[action]]: value }, commandId },
      resultSchema,
    );
  }

  // --- job control ----------------------------------------------------------------------------

  /** GET /cnc/data?action=pause|resume|stop → ok, or fail when the state does not allow it. */
  jobAction(action: 'pause' | 'resume' | 'stop', commandId: string) {
    return this.json({ path: '/cnc/data', query: { action }, commandId }, resultSchema);
  }

  /** GET /read?file= — runs the file immediately: fires the laser. */
  runFile(file: string, commandId: string) {
    return this.json({ path: '/read', query: { file }, commandId }, resultSchema);
  }

  deleteFile(file: string, commandId: string) {
    return this.json({ path: '/delete', query: { file }, commandId }, resultSchema);
  }

  /** One line with GET /cmd?cmd=, several with POST /cmd (plain text body). */
  gcode(code: string, commandId: string) {
    const lines = code
      .split(/\r?\n/)
      .map((l) => l.trim())
      .filter((l) => l !== '');
    if (lines.length <= 1) {
      return this.json({ path: '/cmd', query: { cmd: lines[0] ?? '' }, commandId }, resultSchema);
    }
    return this.json(
      {
        method: 'POST',
        path: '/cmd',
        body: lines.join('\n') + '\n',
        headers: { 'Content-Type': 'text/plain' },
        commandId,
      },
      resultSchema,
    );
  }

  // --- uploads --------------------------------------------------------------------------------

  /**
   * POST /upload (multipart `file`). The laser answers "ok" even when the upload failed, so the
   * caller verifies with /list afterwards (`verifiedUpload` in upload.ts does).
   */
  async upload(
    file: Blob,
    target: UploadTarget,
    commandId: string,
    onProgress?: (p: UploadProgress) => void,
  ): Promise<string> {
    const query: Record<string, string | number> =
      target.kind === 'path' ? { filename: target.filename } : { filetype: target.kind === 'frame' ? 0 : 1 };
    const name = uploadPath(target).split('/').pop() || 'tmp.gcode';
    const res = await this.postMultipart('/upload', query, file, name, commandId, onProgress, 120_000);
    const body = parseJsonLenient(res.text);
    const vendor = parseXtoolError(res.status, body, res.text);
    if (vendor) throw vendor;
    const parsed = resultSchema.safeParse(body);
    if (!parsed.success)
      throw new LinkError('protocol', `Unexpected answer from /upload: ${res.text.slice(0, 80)}`);
    return parsed.data.result;
  }

  /** POST /upgrade (multipart `file`) → "OK" or "FAIL" as plain text. */
  async upgrade(file: Blob, name: string, commandId: string, onProgress?: (p: UploadProgress) => void) {
    const res = await this.postMultipart('/upgrade', {}, file, name, commandId, onProgress, 300_000);
    const parsed = upgradeReplySchema.safeParse(res.text);
    if (!parsed.success) {
      throw new LinkError('protocol', `Unexpected answer from /upgrade: "${res.text.trim().slice(0, 80)}"`, {
        path: '(root)',
      });
    }
    return parsed.data;
  }

  /**
   * Multipart POST with upload progress through XMLHttpRequest where there is one (browser);
   * plain fetch elsewhere (Node tests). Runs in the lane like every other request.
   */
  private postMultipart(
    path: string,
    query: Record<string, string | number>,
    file: Blob,
    filename: string,
    commandId: string,
    onProgress: ((p: UploadProgress) => void) | undefined,
    timeoutMs: number,
  ): Promise<RawResponse> {
    const form = new FormData();
    form.append('file', file, filename);
    return this.lane(
      async () => {
        if (typeof globalThis.XMLHttpRequest === 'undefined') {
          const r = await this.http.raw({ method: 'POST', path, query, body: form, commandId, timeoutMs });
          onProgress?.({ loaded: file.size, total: file.size });
          return r;
        }
        return uploadWithProgress({
          method: 'POST',
          url: this.http.url(path, query),
          body: form,
          headers: { 'X-Shopdeck-Command': commandId },
          onProgress: (p) => {
            this.onTransfer?.();
            onProgress?.(p);
          },
          timeoutMs,
        });
      },
      undefined,
      true,
    );
  }

  /**
   * One request at a time to the laser (an ESP32). HttpClient's own `serial` option covers only
   * its fetches, not XHR uploads, so the client keeps its own lane around both.
   */
  private tail: Promise<unknown> = Promise.resolve();
  /** Requests started and not finished (at most 1), for tests. */
  inFlight = 0;
  maxInFlight = 0;

  /** `transfer`: an upload, whose time says how big the file is, not how slow the link: not an answer time. */
  private lane<T>(run: () => Promise<T>, signal?: AbortSignal, transfer = false): Promise<T> {
    const go = async () => {
      // Cancelled while waiting its turn (the session stopped, the view went away): never sent.
      if (signal?.aborted) throw new LinkError('aborted', 'Request cancelled');
      this.inFlight++;
      this.maxInFlight = Math.max(this.maxInFlight, this.inFlight);
      const sentAt = this.now();
      const answered = () => (transfer ? this.onTransfer?.() : this.onAnswer?.(this.now() - sentAt));
      try {
        const r = await run();
        answered();
        return r;
      } catch (e) {
        // The laser's own words (a refusal, a 404, JSON of another shape) are an answer too.
        if (e instanceof LinkError && e.kind !== 'aborted' && !isLinkFault(e)) answered();
        throw e;
      } finally {
        this.inFlight--;
      }
    };
    const next = this.tail.then(go, go);
    this.tail = next.catch(() => undefined);
    return next;
  }

  private json<S extends z.ZodMiniType>(opts: RequestOptions, schema: S): Promise<z.output<S>> {
    return this.lane(() => this.http.json(opts, schema), opts.signal);
  }

  private system<S extends z.ZodMiniType>(
    action: string,
    schema: S,
    signal?: AbortSignal,
  ): Promise<z.output<S>> {
    return this.json({ path: '/system', query: { action }, signal }, schema);
  }
}
