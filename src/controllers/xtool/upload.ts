import type { StoreApi } from 'zustand/vanilla';
import type { SessionContext } from '../../fleet/contract';
import { LinkError, describeError } from '../../fleet/errors';
import type { RunToken } from '../../fleet/kernel';
import { uploadPath, type UploadTarget, type XtoolClient } from './client';
import { parentDir, type UploadState, type XtoolDetail } from './model';
import { filesKey } from './queries';

/**
 * A job, framing or file upload that is believed only when the laser shows it: the firmware
 * answers "ok" to `POST /upload` whatever happened (SOURCES.md, obs), so the file must be in the
 * `/list` of its folder afterwards, and a job or framing upload must also have loaded it.
 */

export interface UploadArgs {
  file: Blob;
  /** Shown to the operator ("coaster.gcode"). */
  name: string;
  target: UploadTarget;
}

/** What an upload needs of the session. */
export interface UploadHost {
  readonly ctx: SessionContext;
  readonly client: XtoolClient;
  readonly detail: StoreApi<XtoolDetail>;
  /** The session's current run: the upload writes only while the run that started it lasts. */
  run(): RunToken;
  /** Writes the snapshot fields that follow the detail (activity, label, job). */
  publish(): void;
}

export async function verifiedUpload(host: UploadHost, a: UploadArgs, commandId: string): Promise<string> {
  const { client, ctx, detail } = host;
  const run = host.run();
  const path = uploadPath(a.target);
  const start: UploadState = {
    name: a.name,
    path,
    loaded: 0,
    total: a.file.size,
    phase: 'uploading',
    message: null,
  };
  const set = (u: Partial<UploadState>) => {
    if (run.alive()) detail.setState((s) => ({ upload: { ...(s.upload ?? start), ...u } }));
  };
  if (run.alive()) detail.setState({ upload: start, notice: null });
  const dir = parentDir(path);
  const base = path.slice(path.lastIndexOf('/') + 1);
  const has = (names: string[]) =>
    names.some((n) => n === path || n === base || (n.endsWith(`/${base}`) && parentDir(n) === dir));
  try {
    // The firmware answers "ok" even when the upload failed: believe only what the laser shows
    // afterwards. /list has names only, so note whether a file of that name was there before.
    const st = detail.getState().machine.state;
    const wasLoaded = st === 'job-loaded' || st === 'frame-ready';
    const before = await client.list(dir).then(
      (l) => has(l.name),
      () => false,
    );
    await client.upload(a.file, a.target, commandId, (p) => set({ loaded: p.loaded, total: p.total }));
    set({ phase: 'verifying', loaded: a.file.size });
    const list = await client.list(dir);
    if (!has(list.name)) {
      throw new LinkError(
        'vendor',
        `The laser answered "ok" but ${path} is not on the SD card: the upload failed.`,
      );
    }
    let caveat = '';
    if (before && a.target.kind !== 'path') {
      // A job or framing upload loads the file: the laser reports "2" (loaded). Still idle means
      // the old file is on the card and the new one never arrived.
      const w = await client.workingSta();
      if (wasLoaded) {
        caveat = ` A file was already loaded before; the laser cannot show that the new one replaced it.`;
      } else if (w.code === 'idle') {
        throw new LinkError(
          'vendor',
          `The laser answered "ok" but did not load ${path} (it is idle; the file on the card is the old one): the upload failed.`,
        );
      }
    } else if (before) {
      caveat = ` A file of that name was there before; the SD card listing cannot prove the new one replaced it.`;
    }
    // The verification listing is the folder's new listing: it goes into the query layer as it is,
    // so the Files tab shows it without asking the laser a second time.
    if (run.alive()) ctx.queries.set(filesKey(dir), list);
    const armed = a.target.kind !== 'path';
    const message = armed
      ? `${a.name} is on the laser. The ${a.target.kind === 'frame' ? 'framing' : 'job'} starts with the button on the machine.${caveat}`
      : `${a.name} copied to ${path}.${caveat}`;
    set({ phase: 'done', message });
    if (armed && run.alive()) {
      detail.setState((s) => ({ jobName: a.target.kind === 'job' ? a.name : s.jobName, notice: message }));
      host.publish();
    }
    return message;
  } catch (e) {
    set({ phase: 'failed', message: describeError(e) });
    throw e;
  }
}
