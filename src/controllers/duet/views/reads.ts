import { describeError } from '../../../fleet/errors';
import { useMachineQuery } from '../../../fleet/kernel';
import {
  DIR_STALE_MS,
  dirKey,
  FILE_INFO_STALE_MS,
  fileInfoKey,
  HEIGHT_MAP_STALE_MS,
  heightMapKey,
} from '../reads';
import type { DuetSession } from '../session';
import type { DirEntry, HeightMap, ParsedFileInfo } from '../wire';

/** The views' side of `../reads.ts`: each read a query of the machine, shown from cache at once. */

const NO_ENTRIES: DirEntry[] = [];

export interface DirectoryView {
  entries: DirEntry[];
  /** A read is in flight. */
  loading: boolean;
  error: string | null;
  refetch: () => void;
}

/** The listing of `dir` (read while `enabled`: the machine is online). */
export function useDirectory(session: DuetSession, dir: string, enabled: boolean): DirectoryView {
  const q = useMachineQuery(session.ctx.queries, dirKey(dir), session.reads.dir(dir), {
    staleTimeMs: DIR_STALE_MS,
    enabled,
  });
  return {
    // A folder that cannot be listed shows no (old) entries, only why.
    entries: q.error ? NO_ENTRIES : (q.data ?? NO_ENTRIES),
    loading: q.fetching,
    error: q.error ? describeError(q.error) : null,
    refetch: q.refetch,
  };
}

/** File info of a job file, thumbnails included (null while it is read, or when it failed). */
export function useFileInfo(session: DuetSession, path: string): ParsedFileInfo | null {
  const q = useMachineQuery(session.ctx.queries, fileInfoKey(path), session.reads.fileInfo(path), {
    staleTimeMs: FILE_INFO_STALE_MS,
  });
  return q.data ?? null;
}

export interface HeightMapView {
  path: string;
  map: HeightMap | null;
  loading: boolean;
  error: string | null;
  refetch: () => void;
}

/** The height map at `path` (read while `enabled`). */
export function useHeightMap(session: DuetSession, path: string, enabled: boolean): HeightMapView {
  const q = useMachineQuery(session.ctx.queries, heightMapKey(path), session.reads.heightMap(path), {
    staleTimeMs: HEIGHT_MAP_STALE_MS,
    enabled,
  });
  return {
    path,
    map: q.error ? null : (q.data ?? null),
    loading: q.fetching,
    error: q.error ? describeError(q.error) : null,
    refetch: q.refetch,
  };
}
