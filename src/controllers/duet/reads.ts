import type { MachineQueries } from '../../fleet/kernel';
import type { DuetClient } from './client';
import { parseHeightMap, type DirEntry, type HeightMap, type ParsedFileInfo } from './wire';

/**
 * On-demand reads of a Duet: folder listings, file info (with the thumbnails' base64 data) and
 * the height map. They are queries of the machine (`ctx.queries`): one request per key at a
 * time, fresh for a while, refetched after the commands that change them (`invalidates` on the
 * command, or `changed()` for one file), cancelled on stop, and bounded — the query cache drops
 * unobserved entries after a few minutes and keeps at most a few hundred. (File info used to be
 * kept in the session's store forever, thumbnails and all.)
 */

/** Query key parts under the machine ("dir" covers every listing). */
export const READ = { dir: 'dir', fileInfo: 'fileinfo', heightMap: 'heightmap' } as const;

/** A listing is fresh this long (files change by commands, which invalidate it). */
export const DIR_STALE_MS = 5_000;
/** File info of one path: it changes only when the file does (upload, move, delete invalidate it). */
export const FILE_INFO_STALE_MS = 5 * 60_000;
/** The height map is rewritten by G29 (console, macros: those commands invalidate it). */
export const HEIGHT_MAP_STALE_MS = 60_000;
export const DEFAULT_HEIGHT_MAP = '0:/sys/heightmap.csv';

export const dirKey = (dir: string) => [READ.dir, dir] as const;
export const fileInfoKey = (path: string) => [READ.fileInfo, path] as const;
export const heightMapKey = (path: string) => [READ.heightMap, path] as const;

/** The session's read: the request, once more after a silent reconnect on 401/403. */
export type Reader = <T>(fn: (signal: AbortSignal) => Promise<T>, signal: AbortSignal) => Promise<T>;

export type Fetch<T> = (signal: AbortSignal) => Promise<T>;

export class DuetReads {
  constructor(
    private readonly queries: MachineQueries,
    private readonly client: DuetClient,
    private readonly read: Reader,
  ) {}

  /** `GET /machine/directory/{dir}` */
  dir(dir: string): Fetch<DirEntry[]> {
    return (signal) => this.read((s) => this.client.listDirectory(dir, s), signal);
  }

  /** `GET /machine/fileinfo/{path}?readThumbnailContent=true` */
  fileInfo(path: string): Fetch<ParsedFileInfo> {
    return (signal) => this.read((s) => this.client.fileInfo(path, true, s), signal);
  }

  /** The height map CSV, parsed (a file that is not a height map is an error). */
  heightMap(path: string): Fetch<HeightMap> {
    return async (signal) => parseHeightMap(await this.read((s) => this.client.readText(path, s), signal));
  }

  listDir(dir: string): Promise<DirEntry[]> {
    return this.queries.fetch(dirKey(dir), this.dir(dir), { staleTimeMs: DIR_STALE_MS });
  }

  loadFileInfo(path: string): Promise<ParsedFileInfo> {
    return this.queries.fetch(fileInfoKey(path), this.fileInfo(path), { staleTimeMs: FILE_INFO_STALE_MS });
  }

  loadHeightMap(path: string): Promise<HeightMap> {
    return this.queries.fetch(heightMapKey(path), this.heightMap(path), { staleTimeMs: HEIGHT_MAP_STALE_MS });
  }

  /**
   * Files changed (uploaded over, moved, deleted): their info is stale. `null`: a folder moved
   * or was deleted, so any file info under it may be.
   */
  changed(paths: readonly string[] | null): void {
    if (paths === null) void this.queries.invalidate([READ.fileInfo]);
    else for (const p of paths) void this.queries.invalidate(fileInfoKey(p));
  }
}
