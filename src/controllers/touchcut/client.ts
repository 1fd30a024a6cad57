import { LinkError } from '../../fleet/errors';
import {
  connectionLost,
  HttpClient,
  parseJsonLenient,
  NOT_JSON,
  preview,
  type QueryValue,
} from '../../fleet/http';
import { CONSOLE_HEADERS } from '../../fleet/origin';
import { gatewayBodyError, fromGateway } from '../../fleet/faults';
import { LOGIN_PATH } from './gateway';
import {
  errorBodySchema,
  heldLoginSchema,
  machineInfoSchema,
  monitorSchema,
  openDataSchema,
  statsSchema,
  statusSchema,
  type HeldLoginWire,
  type MachineInfoWire,
  type Monitor,
  type OpenData,
  type Stats,
  type Status,
  type UnitsChoice,
} from './wire';

/**
 * Typed client of the TouchCut REST API v1 (manual: "The base URL for the Rest API is:
 * https://<machine IP/name>/rest/v1/"). The browser talks to `/machines/<id>/rest/v1/...`; the
 * gateway forwards over HTTPS (accepting TouchCut's self-signed certificate for this machine only)
 * and adds the TouchCut user's JWT when it holds a login, else `X-TouchCut-API-Key` when the
 * machine has a key.
 *
 * The browser never holds a token: a login is performed by the gateway (`POST rest/v1/auth`),
 * which keeps the JWT for the machine (shared by every viewer) and answers with who is logged in
 * and until when (gateway.ts `HeldLogin`). Nothing here sends `Authorization`.
 */

export const REST = '/rest/v1';

/** Privileges of TouchCut's user-group dialog (manual, "Managing REST API Keys"). */
export const TOUCHCUT_PRIVILEGES = [
  'Modify Setup Params',
  'Modify System Policies',
  'Add Remove Modify System Security',
  'Web Control Move Part Unloader',
  'Monitor System',
  'Add Remove Tools',
  'Add Remove Materials',
  'Add Remove Tool Processes',
  'Modify General Settings Advanced',
  'Modify Tools Advanced',
  'Modify Tool Processes Advanced',
  'Modify Tuning',
  'Confirm Maintenance Done',
  'Modify Dross Bin Settings',
  'Modify Current User',
  'Modify General Settings',
] as const;

/**
 * Which privilege each request needs, for 403 messages. The manual names the 403 ("JWT user does
 * not have the required privileges") but not the privilege; these are the nearest privileges of
 * the group dialog and are shown as "probably".
 */
export const PRIVILEGE_FOR: Record<string, { action: string; privilege: string }> = {
  status: { action: 'reading the machine status', privilege: 'Monitor System' },
  stats: { action: 'reading production statistics', privilege: 'Monitor System' },
  monitor: { action: 'monitoring axes and I/O', privilege: 'Monitor System' },
  programs: { action: 'reading the programs', privilege: 'Monitor System' },
  unloader: { action: 'reading the part unloader', privilege: 'Monitor System' },
  screenshot: { action: 'viewing the screen', privilege: 'Monitor System' },
  'auth/change-password': { action: 'changing the password', privilege: 'Modify Current User' },
};

/** Clear words for the vendor codes of the manual's "Failure Responses". */
export function vendorCodeMessage(code: string, msg: string | undefined): string {
  const m = msg ? ` (“${msg}”)` : '';
  switch (code.trim()) {
    case '1003':
      return `TouchCut: a required parameter is missing${m}`;
    case '1002':
      return /confirm/i.test(msg ?? '')
        ? 'TouchCut: the new password and its confirmation do not match'
        : `TouchCut: a parameter is invalid${m}`;
    case '100':
      return 'TouchCut is still starting (application not ready): try again in a moment';
    case '101':
      return 'TouchCut does not know this user name';
    case '102':
      return 'Wrong TouchCut password';
    case '2000':
      return 'TouchCut could not create a login token (JWT): an internal error on the controller; try again';
    default:
      return `TouchCut error ${code}${m}`;
  }
}

/** The manual's HTTP statuses in words. */
export function statusMessage(status: number, where: string): string {
  switch (status) {
    case 401:
      return `Not logged in to TouchCut, the login expired, or the user has no web access privilege (HTTP 401 from ${where})`;
    case 403:
      return `TouchCut refused: the user's group lacks a privilege for this (HTTP 403 from ${where})`;
    case 405:
      return `TouchCut does not allow this request (HTTP 405 method not allowed from ${where})`;
    default:
      return `HTTP ${status} from ${where}`;
  }
}

/** VendorErrorParser for HttpClient: `{ "code", "msg" }` bodies and the documented statuses. */
export function parseTouchcutError(status: number, body: unknown, text: string): LinkError | null {
  if (status < 400) {
    // A 2xx whose whole body is `{ code, msg }` is an error body sent with the wrong status.
    const keys =
      body && typeof body === 'object' && !Array.isArray(body) ? Object.keys(body).sort().join(',') : '';
    if (keys !== 'code,msg') return null;
  }
  const e = errorBodySchema.safeParse(body);
  if (e.success) {
    return new LinkError('vendor', vendorCodeMessage(e.data.code, e.data.msg), {
      status,
      vendorCode: e.data.code.trim(),
      vendorMessage: e.data.msg ?? null,
    });
  }
  if (status === 401 || status === 403 || status === 405) {
    return new LinkError('http', statusMessage(status, 'TouchCut') + (text ? `: ${preview(text, 80)}` : ''), {
      status,
    });
  }
  return null;
}

export function isNotReady(e: unknown): boolean {
  return e instanceof LinkError && e.vendorCode === '100';
}

/** TouchCut itself answered 401 (the console server's own 401 — no console login — is not TouchCut's). */
export function isUnauthorized(e: unknown): boolean {
  return e instanceof LinkError && e.status === 401 && !fromGateway(e);
}

/** Rewrites a 403 into "which action needs which privilege". */
function explain403(e: unknown, resource: string): unknown {
  if (!(e instanceof LinkError) || e.status !== 403) return e;
  const p = PRIVILEGE_FOR[resource];
  const what = p
    ? `${p.action} needs the “${p.privilege}” privilege (probably; the manual does not name it)`
    : resource;
  return new LinkError(
    'http',
    `TouchCut refused ${resource} (HTTP 403): the user's or API key's group lacks a privilege — ${what}`,
    {
      status: 403,
      vendorCode: e.vendorCode,
      vendorMessage: e.vendorMessage,
    },
  );
}

export interface StatsQuery {
  /** yyyy-mm-dd, first day */
  startDate?: string;
  /** yyyy-mm-dd, first day NOT included */
  endBeforeDate?: string;
  condensed?: boolean;
  units?: UnitsChoice;
}

export interface ProgramsQuery {
  offset?: number;
  limit?: number;
  onlyChangedData?: boolean;
  fields?: string;
  units?: UnitsChoice;
}

export interface UnloaderQuery {
  history?: boolean;
  startDate?: string;
  endBeforeDate?: string;
  units?: UnitsChoice;
}

export interface Screenshot {
  blob: Blob;
  bytes: number;
}

const PNG_SIGNATURE = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];

/** `units` is only sent when the user chose something else than TouchCut's own default. */
function unitsParam(u: UnitsChoice | undefined): QueryValue {
  return u && u !== 'default' ? u : undefined;
}

/**
 * A request's own timeout. The gateway reaches TouchCut over HTTPS with a new connection per
 * request (its sharing declaration: keep-alive off): under 2 s latency each way that is a TCP
 * handshake, a TLS handshake (one or two round trips) and the request, 12 to 16 s. A silent link
 * is shown long before (the session's liveness window); this only ends the wait.
 */
export const REQUEST_TIMEOUT_MS = 20_000;

export class TouchcutClient {
  readonly http: HttpClient;

  constructor(
    readonly machineId: string,
    opts: { timeoutMs?: number } = {},
  ) {
    this.http = new HttpClient({
      machineId,
      timeoutMs: opts.timeoutMs ?? REQUEST_TIMEOUT_MS,
      // The console server's own failure body first: its 502 or 401 is never TouchCut's answer.
      parseError: (status, body, text) =>
        gatewayBodyError(status, body) ?? parseTouchcutError(status, body, text),
    });
  }

  private async get<T>(resource: string, run: (path: string) => Promise<T>): Promise<T> {
    try {
      return await run(`${REST}/${resource}`);
    } catch (e) {
      throw explain403(e, resource);
    }
  }

  /** `GET rest/v1/machine-info` — no login needed. */
  machineInfo(signal?: AbortSignal): Promise<MachineInfoWire> {
    return this.http.json({ path: `${REST}/machine-info`, signal }, machineInfoSchema);
  }

  status(units?: UnitsChoice, signal?: AbortSignal): Promise<Status> {
    const query = { units: unitsParam(units) };
    return this.get('status', (path) => this.http.json({ path, query, signal }, statusSchema));
  }

  stats(q: StatsQuery = {}, signal?: AbortSignal): Promise<Stats> {
    const query: Record<string, QueryValue> = {
      'start-date': q.startDate,
      'end-before-date': q.endBeforeDate,
      condensed: q.condensed ? 'true' : undefined,
      units: unitsParam(q.units),
    };
    // Stats of a long range are read from many daily .ini files: give it longer.
    return this.get('stats', (path) =>
      this.http.json({ path, query, timeoutMs: 30_000, signal }, statsSchema),
    );
  }

  /** `fields`: comma separated, `*` wildcard per group ("axes.*,io.din"). */
  monitor(fields?: readonly string[], units?: UnitsChoice, signal?: AbortSignal): Promise<Monitor> {
    const query: Record<string, QueryValue> = {
      fields: fields && fields.length > 0 ? fields.join(',') : undefined,
      units: unitsParam(units),
    };
    return this.get('monitor', (path) => this.http.json({ path, query, signal }, monitorSchema));
  }

  programs(q: ProgramsQuery = {}, signal?: AbortSignal): Promise<OpenData> {
    const query: Record<string, QueryValue> = {
      offset: q.offset,
      limit: q.limit,
      onlyChangedData: q.onlyChangedData ? 'true' : undefined,
      fields: q.fields,
      units: unitsParam(q.units),
    };
    return this.get('programs', (path) => this.http.json({ path, query, signal }, openDataSchema));
  }

  unloader(q: UnloaderQuery = {}, signal?: AbortSignal): Promise<OpenData> {
    const query: Record<string, QueryValue> = {
      history: q.history ? 'true' : undefined,
      'start-date': q.startDate,
      'end-before-date': q.endBeforeDate,
      units: unitsParam(q.units),
    };
    return this.get('unloader', (path) => this.http.json({ path, query, signal }, openDataSchema));
  }

  /**
   * `GET rest/v1/screenshot` → image/png. Read with fetch directly (HttpClient.blob does not check
   * the HTTP status): non-2xx goes through the same error parser, anything that is not a PNG is a
   * protocol error. Rate limiting is the caller's job (ScreenshotFeed).
   */
  async screenshot(signal?: AbortSignal, timeoutMs = REQUEST_TIMEOUT_MS): Promise<Screenshot> {
    const path = `${REST}/screenshot`;
    const ctrl = new AbortController();
    let timedOut = false;
    const timer = setTimeout(() => {
      timedOut = true;
      ctrl.abort();
    }, timeoutMs);
    const onAbort = () => ctrl.abort();
    signal?.addEventListener('abort', onAbort);
    try {
      let res: Response;
      try {
        res = await globalThis.fetch(this.http.url(path), {
          headers: { ...CONSOLE_HEADERS },
          signal: ctrl.signal,
          credentials: 'same-origin',
        });
      } catch (e) {
        if (timedOut) throw new LinkError('timeout', `No answer from ${path} within ${timeoutMs / 1000} s`);
        if (signal?.aborted) throw new LinkError('aborted', 'Request cancelled');
        throw new LinkError('network', connectionLost(e instanceof Error ? e.message : String(e)));
      }
      // The image stays the browser's own blob: copying it into script and back into a new Blob
      // held the main thread ~50 ms when a fleet page's TouchCut thumbnails came together.
      const whole = await res.blob();
      if (!res.ok) {
        const text = await whole.slice(0, 2000).text();
        const body = parseJsonLenient(text);
        throw (
          gatewayBodyError(res.status, body) ??
          parseTouchcutError(res.status, body === NOT_JSON ? null : body, text) ??
          new LinkError('http', `HTTP ${res.status} from ${path}`, { status: res.status })
        );
      }
      const head = new Uint8Array(await whole.slice(0, PNG_SIGNATURE.length).arrayBuffer());
      if (!PNG_SIGNATURE.every((b, i) => head[i] === b)) {
        const text = await whole.slice(0, 200).text();
        throw new LinkError(
          'protocol',
          `Unexpected answer from ${path}: not a PNG image (${preview(text, 60)})`,
          {
            path: '(root)',
          },
        );
      }
      return {
        blob: whole.type === 'image/png' ? whole : whole.slice(0, whole.size, 'image/png'),
        bytes: whole.size,
      };
    } catch (e) {
      throw explain403(e, 'screenshot');
    } finally {
      clearTimeout(timer);
      signal?.removeEventListener('abort', onAbort);
    }
  }

  /**
   * `POST rest/v1/auth` (username, password), performed by the gateway: the JWT stays there, the
   * answer says who is logged in and until when. A refusal is thrown with clear words.
   */
  async login(username: string, password: string, commandId?: string): Promise<HeldLoginWire> {
    const res = await this.http.json(
      {
        method: 'POST',
        path: LOGIN_PATH,
        // The manual lists "Parameters: username, password" without saying where; a form body
        // keeps the password out of URLs and proxy logs (the simulator accepts query, form and JSON).
        body: new URLSearchParams({ username, password }),
        headers: { 'Content-Type': 'application/x-www-form-urlencoded' },
        commandId,
      },
      heldLoginSchema,
    );
    if (!res.loggedIn || res.success === false)
      throw new LinkError('vendor', 'TouchCut refused the login', { status: 200 });
    return res;
  }

  /** Who the gateway is logged in to TouchCut as for this machine (`GET rest/v1/auth`, the gateway's). */
  loginState(signal?: AbortSignal): Promise<HeldLoginWire> {
    return this.http.json({ path: LOGIN_PATH, signal }, heldLoginSchema);
  }

  /** Ends the machine's TouchCut user login in the gateway, for every viewer (`DELETE rest/v1/auth`). */
  async logout(commandId?: string): Promise<void> {
    await this.http.raw({ method: 'DELETE', path: LOGIN_PATH, commandId });
  }

  /**
   * `POST rest/v1/auth/change-password` — needs the user login the gateway holds (not an API key);
   * the gateway keeps the new JWT and answers with the login's new expiry.
   */
  async changePassword(
    p: { oldPassword: string; newPassword: string; confirmPassword: string },
    commandId: string,
  ): Promise<HeldLoginWire> {
    try {
      return await this.http.json(
        {
          method: 'POST',
          path: `${REST}/auth/change-password`,
          body: new URLSearchParams({
            'old-password': p.oldPassword,
            'new-password': p.newPassword,
            'confirm-password': p.confirmPassword,
          }),
          headers: { 'Content-Type': 'application/x-www-form-urlencoded' },
          commandId,
        },
        heldLoginSchema,
      );
    } catch (e) {
      throw explain403(e, 'auth/change-password');
    }
  }
}
