import { LinkError } from '../../fleet/errors';
import { gatewayBodyError } from '../../fleet/faults';
import { HttpClient, type VendorErrorParser } from '../../fleet/http';
import { statusText } from './codes';
import {
  createdId,
  errorBody,
  jobListResponse,
  jobResponse,
  machineTreeResponse,
  machineValueResponse,
  operationListResponse,
  operationResponse,
  shallowResponse,
  statusReportResponse,
  valueForKey,
  versionResponse,
  type Job,
  type Operation,
  type Scalar,
  type SettingsGroup,
  type SrValues,
  type VersionInfo,
} from './wire';

/**
 * Typed client of the g2core REST interface (../shared/protocols/g2core-rest-design.txt).
 *
 * The design is PRELIMINARY and no public server implements it: this client is its first
 * consumer. Its open points are settled here (and in README.md) so a server author can match:
 *
 *  1. Filters. Browsers cannot send a body with GET, so the JSON the design puts in the body goes
 *     in a `filter` query parameter: `GET /machine?filter={"x":null,"y":{"jm":null}}`,
 *     `GET /status_report?filter={"posx":null}`. Null selects a key; a non-null value means
 *     "return it only if it differs from this" (the design's "only what changed").
 *     `GET /machine?shallow=true` lists the top-level groups.
 *  2. Keys. `/machine/x/vm`, `/machine/xvm` and `/machine/x.vm` address the same value. The
 *     client sends the nested form for group keys and the freestanding form for system keys
 *     (`/machine/ct`, as the design does), and accepts any form in answers.
 *  3. `PUT /machine/{key}` carries the JSON value (a number, or an object for groups such as
 *     `g54`) and answers `{"value":…}` (bare or echoed under the key).
 *  4. Operations. `POST /operation {"optype":"run","value":[lines]|"text"}` → 201 with the id;
 *     `GET /operation/{id}` → `{"opstate":"pend|run|pause|done|error","optype","value","line","error"?}`
 *     (`line` = lines finished; `pause` while held; `r`: replies of its JSON lines, in order);
 *     `PUT /operation/{id} {"opstate":"pause"|"run"|"kill"}` = feedhold, cycle start, queue
 *     flush + job kill. `{"optype":"sendfile","value":<job id>}` runs a file.
 *  5. Jobs. `POST /job` (JSON `{"name","gcode"}` or multipart with a `file` field) → 201 with the
 *     id; `GET /job` lists the queue; `GET /job/{id}` → `{"id","name","state":"queued|running|
 *     paused|done|killed|error","lines","done","started","finished","operation","position"}`;
 *     `PUT /job/{id}` with `{"state":"run"|"pause"|"kill"}` or `{"position":n}` (queue order).
 *  6. Errors. `{"status":{"code","description","additional_description"}}` with the HTTP status
 *     of the design's table (codes.ts `httpStatusFor`). The console shows the firmware text of
 *     the code from the status-code table, then the additional description.
 *  7. Alarm clear is the firmware's `{"clear":null}` as a resource read: `GET /machine/clear`
 *     (a GET that is a command: audited, operator role).
 *  8. `GET /operation` lists the operations the server knows (unfinished first, in the order
 *     they run, then recent finished ones), each as `GET /operation/{id}` answers with its `id`.
 *     The design has no machine-wide feedhold, so this is how a console finds motion that
 *     another console started and holds or kills it. A server without it answers 404/405; the
 *     console then can only hold what it started itself, and says so.
 */

export type FilterSpec = Record<string, Scalar | Record<string, Scalar>>;

/** The g2core status behind an error, when the controller sent one. */
export interface G2Status {
  code: number;
  /** The firmware text from the status-code table. */
  text: string;
  additional: string | null;
  http: number | null;
}

export function g2StatusOf(e: unknown): G2Status | null {
  if (!(e instanceof LinkError) || e.kind !== 'vendor' || e.vendorCode === null) return null;
  const code = Number(e.vendorCode);
  if (!Number.isFinite(code)) return null;
  return { code, text: statusText(code), additional: e.vendorMessage, http: e.status };
}

/** Turns `{"status":{…}}` bodies (any HTTP status) into a vendor LinkError with the table text. */
export const parseG2Error: VendorErrorParser = (status, body) => {
  const ok = status >= 200 && status < 300;
  const parsed = errorBody.safeParse(body);
  if (!parsed.success) {
    // A success body of the design examples may carry "code":<n> next to the value.
    if (ok && typeof body === 'object' && body !== null && 'code' in body) {
      const code = Number((body as { code: unknown }).code);
      if (Number.isFinite(code) && code !== 0 && code !== 3 && code !== 4)
        return vendorError(status, code, null, null);
    }
    return null;
  }
  const { code, description, additional_description } = parsed.data.status;
  if (ok && (code === 0 || code === 3 || code === 4)) return null;
  return vendorError(status, code, description ?? null, additional_description ?? null);
};

function vendorError(status: number, code: number, description: string | null, additional: string | null) {
  const known = statusText(code);
  const text = known.startsWith('Status ') && description ? description : known;
  return new LinkError('vendor', `${text}${additional ? ` — ${additional}` : ''} (status ${code})`, {
    status,
    vendorCode: String(code),
    vendorMessage: additional ?? description,
  });
}

/** The path of a key: nested for group keys, freestanding for system keys and groups. */
export function keyPath(group: string | null, key: string): string {
  const k = encodeURIComponent(key);
  return group ? `/machine/${encodeURIComponent(group)}/${k}` : `/machine/${k}`;
}

export type OpControl = 'pause' | 'run' | 'kill';
export type JobControl = { state: 'run' | 'pause' | 'kill' } | { position: number };

export class G2coreClient {
  readonly http: HttpClient;

  constructor(machineId: string, opts: { timeoutMs?: number } = {}) {
    this.http = new HttpClient({
      machineId,
      timeoutMs: opts.timeoutMs ?? 5000,
      // The console server's own failure body first: its answer is never the controller's.
      parseError: (status, body, text) => gatewayBodyError(status, body) ?? parseG2Error(status, body, text),
    });
  }

  version(signal?: AbortSignal): Promise<VersionInfo> {
    return this.http.json({ path: '/version', signal }, versionResponse);
  }

  /** Status report; `filter` null values select keys, non-null values return only changed keys. */
  statusReport(filter?: Record<string, Scalar>, signal?: AbortSignal): Promise<SrValues> {
    return this.http.json(
      { path: '/status_report', query: { filter: filter ? JSON.stringify(filter) : undefined }, signal },
      statusReportResponse,
    );
  }

  /** Top-level objects of the machine (`shallow=true`). */
  async groups(signal?: AbortSignal): Promise<string[]> {
    const r = await this.http.json({ path: '/machine', query: { shallow: 'true' }, signal }, shallowResponse);
    return Object.keys(r.value);
  }

  /** The machine tree, or the part a filter selects. Freestanding keys come back as scalars. */
  async machine(filter?: FilterSpec, signal?: AbortSignal): Promise<Record<string, SettingsGroup | Scalar>> {
    const r = await this.http.json(
      { path: '/machine', query: { filter: filter ? JSON.stringify(filter) : undefined }, signal },
      machineTreeResponse,
    );
    return r.value;
  }

  /** One group ("x", "1", "g54"). */
  async group(name: string, signal?: AbortSignal): Promise<SettingsGroup> {
    const r = await this.machine({ [name]: null }, signal);
    const g = r[name];
    if (typeof g !== 'object' || g === null) {
      throw new LinkError('protocol', `Unexpected answer from /machine: group "${name}" missing`, {
        path: name,
      });
    }
    return g;
  }

  async getKey(group: string | null, key: string): Promise<unknown> {
    const r = await this.http.json({ path: keyPath(group, key) }, machineValueResponse);
    return valueForKey(r.value, group, key);
  }

  /** PUT /machine/{key} with the JSON value; resolves with the value the controller reports back. */
  async setKey(group: string | null, key: string, value: unknown, commandId: string): Promise<unknown> {
    const r = await this.http.json(
      { method: 'PUT', path: keyPath(group, key), json: value, commandId },
      machineValueResponse,
    );
    return valueForKey(r.value, group, key);
  }

  /** Alarm clear: the firmware's `{"clear":null}` as `GET /machine/clear`. */
  async clearAlarm(commandId: string): Promise<void> {
    await this.http.json({ path: '/machine/clear', commandId }, machineValueResponse);
  }

  /**
   * The hard reset (^X) of a board the gateway drives over USB serial (src/controllers/g2core/server/):
   * `POST /board/reset`, answered by the gateway's bridge (a REST g2core has no such endpoint).
   */
  async resetBoard(commandId: string): Promise<void> {
    await this.http.json({ method: 'POST', path: '/board/reset', commandId }, machineValueResponse);
  }

  /** Runs G-code / JSON lines as an operation; resolves with its id. */
  runOperation(value: string[] | string, commandId: string): Promise<string> {
    return this.http.json(
      { method: 'POST', path: '/operation', json: { optype: 'run', value }, commandId },
      createdId,
    );
  }

  /** Runs an uploaded job file as an operation. */
  sendFile(jobId: string, commandId: string): Promise<string> {
    return this.http.json(
      { method: 'POST', path: '/operation', json: { optype: 'sendfile', value: jobId }, commandId },
      createdId,
    );
  }

  /**
   * Every operation the server knows, unfinished ones first (settled point 8): lets any console
   * hold or kill motion that another console started.
   */
  operations(signal?: AbortSignal): Promise<Operation[]> {
    return this.http.json({ path: '/operation', signal }, operationListResponse);
  }

  operation(id: string, signal?: AbortSignal): Promise<Operation> {
    return this.http.json({ path: `/operation/${encodeURIComponent(id)}`, signal }, operationResponse);
  }

  controlOperation(id: string, opstate: OpControl, commandId: string): Promise<Operation> {
    return this.http.json(
      { method: 'PUT', path: `/operation/${encodeURIComponent(id)}`, json: { opstate }, commandId },
      operationResponse,
    );
  }

  jobs(signal?: AbortSignal): Promise<Job[]> {
    return this.http.json({ path: '/job', signal }, jobListResponse);
  }

  job(id: string): Promise<Job> {
    return this.http.json({ path: `/job/${encodeURIComponent(id)}` }, jobResponse);
  }

  /** Queues a job from G-code text, or from a file (multipart, field `file`). */
  createJob(
    src: { name: string; gcode: string } | { file: Blob; name: string },
    commandId: string,
  ): Promise<string> {
    if ('gcode' in src) {
      return this.http.json(
        {
          method: 'POST',
          path: '/job',
          json: { name: src.name, gcode: src.gcode },
          commandId,
          timeoutMs: 60_000,
        },
        createdId,
      );
    }
    const form = new FormData();
    form.append('file', src.file, src.name);
    form.append('name', src.name);
    return this.http.json(
      { method: 'POST', path: '/job', body: form, commandId, timeoutMs: 120_000 },
      createdId,
    );
  }

  controlJob(id: string, control: JobControl, commandId: string): Promise<Job> {
    return this.http.json(
      { method: 'PUT', path: `/job/${encodeURIComponent(id)}`, json: control, commandId },
      jobResponse,
    );
  }
}
