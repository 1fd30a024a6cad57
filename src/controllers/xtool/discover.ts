import { LinkError, protocolError } from '../../fleet/errors';
import { parseJsonLenient, preview } from '../../fleet/http';
import { apiOrigin, CONSOLE_HEADERS } from '../../fleet/origin';
import { discoveryResponseSchema, type DiscoveryReply, type DiscoveryResponse } from './wire';

/**
 * "Find lasers": the browser cannot send UDP, so the gateway broadcasts {"requestId":n} to port
 * 20000 and listens on UDP 20000 and TCP 20001 for two seconds (GET /api/discover/xtool).
 */
export async function discoverLasers(signal?: AbortSignal): Promise<DiscoveryResponse> {
  let res: Response;
  try {
    res = await globalThis.fetch(`${apiOrigin()}/api/discover/xtool`, {
      signal,
      credentials: 'same-origin',
      headers: CONSOLE_HEADERS,
    });
  } catch (e) {
    throw new LinkError(
      'network',
      `Cannot reach the console's server (${e instanceof Error ? e.message : String(e)})`,
    );
  }
  const text = await res.text();
  if (!res.ok)
    throw new LinkError('http', `HTTP ${res.status} from discovery${text ? `: ${preview(text)}` : ''}`);
  const body = parseJsonLenient(text);
  const parsed = discoveryResponseSchema.safeParse(body);
  if (!parsed.success) throw protocolError('/api/discover/xtool', parsed.error);
  return parsed.data;
}

export interface MachineEntry {
  id: string;
  name: string;
  kind: 'xtool';
  url: string;
}

/** The machines-file entry for a reply (DESIGN.md: id [a-z0-9-]{1,40}, HTTP API on :8080). */
export function machineEntry(r: DiscoveryReply, taken: ReadonlySet<string> = new Set()): MachineEntry {
  const fromName = r.name
    .toLowerCase()
    .replace(/[^a-z0-9]+/g, '-')
    .replace(/^-+|-+$/g, '')
    .slice(0, 30);
  const base = fromName || `xtool-${r.ip.replace(/[^0-9a-z]+/gi, '-').toLowerCase()}`.slice(0, 36);
  let id = base;
  for (let i = 2; taken.has(id); i++) id = `${base}-${i}`;
  return { id, name: r.name || `xTool at ${r.ip}`, kind: 'xtool', url: `http://${r.ip}:8080` };
}
