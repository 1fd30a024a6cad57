import { LinkError } from '../../fleet/errors';
import {
  HttpClient,
  preview,
  uploadWithProgress,
  type UploadProgress,
  type VendorErrorParser,
} from '../../fleet/http';
import type { FlatPatch, ModulePatch, PruntApi } from './config-ir';
import {
  configSchemaSchema,
  configValuesSchema,
  runCommandReplySchema,
  statusSchemaSchema,
  statusValuesSchema,
  updateCheckSchema,
  uploadsSchema,
} from './wire';
import { parseJsonLenient, NOT_JSON } from '../../fleet/http';
import { resolveWithin } from '../../ui/safe-url';
import { gatewayBodyError } from '../../fleet/faults';

/**
 * Typed client for the Prunt web API, one method per endpoint, on the console's HttpClient
 * (`/machines/<id>/…`). Prunt answers failures with 500 and a plain-text body ("Can not run file
 * while another file is running."): that text becomes a `vendor` LinkError shown as it is.
 */
export const parsePruntError: VendorErrorParser = (status, body, text) => {
  // The console server's own failure (`{"error","gateway":true}`) is never Prunt's words.
  const own = gatewayBodyError(status, body);
  if (own) return own;
  if (status >= 400 && text.trim() !== '' && !text.trim().startsWith('<')) {
    return new LinkError('vendor', text.trim(), { status, vendorMessage: text.trim() });
  }
  return null;
};

export interface CommandOpts {
  commandId: string;
}

export class PruntClient {
  readonly http: HttpClient;

  constructor(machineId: string, http?: HttpClient) {
    this.http = http ?? new HttpClient({ machineId, timeoutMs: 10_000, parseError: parsePruntError });
  }

  // --- Configuration -------------------------------------------------------------------------

  /** `GET /config/schema`; also returns the raw text (the flat API's schema has no version: we hash it). */
  async configSchema(signal?: AbortSignal) {
    const res = await this.http.raw({ path: '/config/schema', timeoutMs: 20_000, signal });
    const body = parseJsonLenient(res.text);
    if (body === NOT_JSON)
      throw new LinkError(
        'protocol',
        `Unexpected answer from /config/schema: not JSON (${preview(res.text)})`,
        { path: '(root)' },
      );
    const parsed = configSchemaSchema.safeParse(body);
    if (!parsed.success) {
      const issue = parsed.error.issues[0];
      const path = issue ? issue.path.map(String).join('.') : '(root)';
      throw new LinkError(
        'protocol',
        `Unexpected answer from /config/schema at "${path}": ${issue?.message ?? 'invalid'}`,
        { path },
      );
    }
    return { wire: parsed.data, text: res.text };
  }

  /**
   * `GET /config/values`: a read (Prunt writes its config file only at its start and on a save).
   * Not polled: called when the editor opens, on "Reload" and after a server restart.
   */
  configValues(signal?: AbortSignal) {
    return this.http.json({ path: '/config/values', timeoutMs: 20_000, signal }, configValuesSchema);
  }

  /** `POST /config/values`: 200 even when rejected; the reply's Errors say what happened. */
  saveConfig(patch: FlatPatch | ModulePatch, o: CommandOpts) {
    return this.http.json(
      { method: 'POST', path: '/config/values', json: patch, commandId: o.commandId, timeoutMs: 20_000 },
      configValuesSchema,
    );
  }

  // --- Status --------------------------------------------------------------------------------

  statusSchema(signal?: AbortSignal) {
    return this.http.json({ path: '/status/schema', signal }, statusSchemaSchema);
  }

  statusValues(signal?: AbortSignal) {
    return this.http.json({ path: '/status/values', signal }, statusValuesSchema);
  }

  // --- Machine control -----------------------------------------------------------------------

  async pause(o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/pause/pause', commandId: o.commandId });
  }

  async resume(o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/pause/resume', commandId: o.commandId });
  }

  /** `POST /cancel` — newer (module API) servers only. */
  async cancel(o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/cancel', commandId: o.commandId });
  }

  /** `POST /run-file` with the file name as the body: 204, or 500 with the reason. */
  async runFile(name: string, o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/run-file', body: name, commandId: o.commandId });
  }

  /** `POST /run-command`: 204 (flat API) or `{"ID":"…"}` (newer servers). Returns the ID when there is one. */
  async runCommand(command: string, o: CommandOpts): Promise<string | null> {
    const res = await this.http.raw({
      method: 'POST',
      path: '/run-command',
      body: command,
      commandId: o.commandId,
    });
    if (res.status === 204 || res.text.trim() === '') return null;
    const body = parseJsonLenient(res.text);
    const r = runCommandReplySchema.safeParse(body === NOT_JSON ? null : body);
    return r.success ? r.data.ID : null;
  }

  async reloadServer(o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/reload-server', commandId: o.commandId });
  }

  async allowFirmwareUpdate(o: CommandOpts): Promise<void> {
    await this.http.raw({ method: 'POST', path: '/allow-firmware-update', commandId: o.commandId });
  }

  // --- Files ---------------------------------------------------------------------------------

  uploads(signal?: AbortSignal) {
    return this.http.json({ path: '/uploads/', signal }, uploadsSchema);
  }

  /**
   * The URL of an uploaded file, or null when the name (it comes from the controller's list) would
   * lead anywhere but a file in this machine's `/machines/<id>/uploads/`: `..`, `.`, names with a
   * slash or backslash (`../../acc-laser/system?x` is sent as one encoded segment, which a proxy
   * that decodes once would read as a way out).
   */
  fileUrl(name: string): string | null {
    return resolveWithin(encodeURIComponent(name), this.http.url('/uploads/'));
  }

  /** The checked controller path of an uploaded file; throws for a name `fileUrl` refuses. */
  private filePath(name: string): string {
    if (this.fileUrl(name) === null)
      throw new LinkError('protocol', `Refused file name "${preview(name, 60)}": not a file in /uploads/`, {
        path: '(root)',
      });
    return `/uploads/${encodeURIComponent(name)}`;
  }

  async download(name: string): Promise<Blob> {
    return (await this.http.blob({ path: this.filePath(name) })).blob;
  }

  /** `PUT /uploads/<name>` with progress. */
  async upload(
    name: string,
    body: Blob | string,
    o: CommandOpts & { onProgress?: (p: UploadProgress) => void; signal?: AbortSignal },
  ) {
    const url = this.http.url(this.filePath(name));
    try {
      await uploadWithProgress({
        method: 'PUT',
        url,
        body,
        headers: { 'X-Shopdeck-Command': o.commandId },
        ...(o.onProgress ? { onProgress: o.onProgress } : {}),
        ...(o.signal ? { signal: o.signal } : {}),
      });
    } catch (e) {
      // Prunt's plain-text 500 bodies are shown as they are.
      if (e instanceof LinkError && e.status && e.status >= 400) {
        const text = e.message.replace(/^HTTP \d+ from upload: /, '');
        throw new LinkError('vendor', text, { status: e.status, vendorMessage: text });
      }
      throw e;
    }
  }

  // --- Maintenance ---------------------------------------------------------------------------

  /** The last update check: `/update-check` (module API) or `/update_check` (flat API). 500 when it timed out. */
  updateCheck(api: PruntApi, signal?: AbortSignal) {
    return this.http.json(
      { path: api === 'module' ? '/update-check' : '/update_check', signal },
      updateCheckSchema,
    );
  }
}
