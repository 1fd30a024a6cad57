import { useStore } from 'zustand';
import type { StoreApi } from 'zustand/vanilla';
import type { SessionContext } from '../../fleet/contract';
import { LinkError } from '../../fleet/errors';
import { useMachineQuery, type Fetcher, type QueryView, type RunToken } from '../../fleet/kernel';
import type { XtoolClient } from './client';
import type { XtoolDetail, XtoolSettings } from './model';
import type { FileList } from './wire';

/**
 * On-demand reads of an xTool laser, through the console's query layer (`ctx.queries`): the
 * settings (`/peripherystatus`, `offset`, `dotMode`) and the SD card listings (`/list?dir=`).
 * Keyed under the machine; one request per key at a time (the laser's lane still serializes every
 * request); cancelled and dropped when the session stops; an unobserved answer is dropped after a
 * while. Commands that change them declare it (`invalidates`), and whatever shows them refetches.
 */

export const SETTINGS_KEY = ['settings'] as const;
export const FILES_KEY = ['files'] as const;
export const filesKey = (dir: string) => ['files', dir] as const;

/**
 * Settings (/peripherystatus: SD card, safety switches, flame alarm) count as fresh this long. The
 * session re-reads them after a status poll while the laser is idle once they are older: the vendor
 * app or the machine itself may change them, and a safety page showing "flame alarm: high" after
 * someone turned it off elsewhere is worse than one more request a minute. Decision: not while
 * busy, to keep the ESP32's lane free for the job polls.
 */
export const SETTINGS_REFRESH_MS = 60_000;

/** A folder listing shown again within this time is not read again (Refresh reads it). */
export const FILES_STALE_MS = 30_000;

export interface ReadHost {
  readonly ctx: SessionContext;
  readonly client: XtoolClient;
  readonly detail: StoreApi<XtoolDetail>;
  /** The session's current run: nothing is asked of a stopped session, nothing written after it. */
  run(): RunToken;
}

export class XtoolReads {
  constructor(private readonly host: ReadHost) {}

  /** `/peripherystatus`, offset and dot mode; the periphery also goes into the detail store. */
  readonly settings: Fetcher<XtoolSettings> = async (signal) => {
    const run = this.live();
    const { client } = this.host;
    const periphery = await client.peripheryStatus(signal).catch((e: unknown) => {
      if (e instanceof LinkError && e.kind === 'vendor') return null;
      throw e;
    });
    // Not every firmware knows these two: a missing one is shown as "not reported".
    const optional = (e: unknown) => {
      if (e instanceof LinkError && e.kind === 'aborted') throw e;
      return null;
    };
    const offset = await client.offset(signal).catch(optional);
    const dot = await client.dotMode(signal).catch(optional);
    if (run.alive()) this.host.detail.setState({ periphery });
    return { periphery, offset: offset ? { x: offset.x, y: offset.y } : null, dotMode: dot?.dotMode ?? null };
  };

  /** `/list?dir=`: the names in one folder of the SD card. */
  files(dir: string): Fetcher<FileList> {
    return async (signal) => {
      this.live();
      return this.host.client.list(dir, signal);
    };
  }

  /** The settings, read again when older than `maxAgeMs` (0: now; one read in flight is shared). */
  refreshSettings(maxAgeMs = 0): Promise<XtoolSettings> {
    return this.host.ctx.queries.fetch(SETTINGS_KEY, this.settings, { staleTimeMs: maxAgeMs });
  }

  private live(): RunToken {
    const run = this.host.run();
    if (!run.alive()) throw new LinkError('offline', 'The laser is not connected');
    return run;
  }
}

/** What a view needs to read: the session's context and reads. */
export interface ReadsOf {
  readonly ctx: SessionContext;
  readonly reads: XtoolReads;
}

function useOnline(s: ReadsOf): boolean {
  return useStore(s.ctx.snapshot, (x) => x.link === 'online');
}

/** The settings for the Safety tab: from cache at once, read when older than a minute. */
export function useXtoolSettings(s: ReadsOf): QueryView<XtoolSettings> {
  const online = useOnline(s);
  return useMachineQuery(s.ctx.queries, SETTINGS_KEY, s.reads.settings, {
    staleTimeMs: SETTINGS_REFRESH_MS,
    enabled: online,
  });
}

/** One folder of the SD card for the Files tab. */
export function useXtoolFiles(s: ReadsOf, dir: string): QueryView<FileList> {
  const online = useOnline(s);
  return useMachineQuery(s.ctx.queries, filesKey(dir), s.reads.files(dir), {
    staleTimeMs: FILES_STALE_MS,
    enabled: online,
  });
}
