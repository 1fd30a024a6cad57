import type { SharedStreamDecl } from '../src/fleet/contract';
import type { GatewayContext } from './context';
import { holdSocket, type HeldSocket } from './held-session';
import type { MachineEntry } from './machines';
import { redactFrame } from './redact';
import { StreamHubs, streamQuery } from './stream-hubs';
import { simUpstream, StreamHub, wsUpstream } from './streams';
import type { createSocketOpener } from './controller-socket';

/** A machine's shared streams (streams.ts): browsers and the gateway's watch join their hub. */
export function createStreamJoin(
  ctx: GatewayContext,
  openControllerSocket: ReturnType<typeof createSocketOpener>,
) {
  const { simulatorFor, streams, patternsFor, hintsOf } = ctx;

  /**
   * The machine's shared hub for this stream: the open one, or a new one opened once. It is named
   * by the declared path and the declared query (`streamQuery`), never by the browser's spelling,
   * and that is what goes upstream: one controller socket per machine and declared stream.
   */
  async function joinHub(
    m: MachineEntry,
    decl: SharedStreamDecl,
    query: string,
    held: HeldSocket | null,
  ): Promise<StreamHub | { status: number; error: string }> {
    const path = decl.path;
    // Filtered here too, whatever the caller passed (streamQuery is idempotent): the key and the
    // upstream URL never hold a browser's own query string (one upstream per declared stream).
    const rawQuery = streamQuery(decl, query);
    if (rawQuery instanceof Error) return { status: 400, error: rawQuery.message };
    const key = StreamHubs.key(m.id, path, rawQuery);
    return streams.get(key, async () => {
      const patterns = patternsFor(m);
      const hubOpts = {
        toClient: patterns.length
          ? (data: Buffer, isBinary: boolean) => redactFrame(data, isBinary, patterns)
          : undefined,
        warn: (msg: string) => ctx.log.warn(`${m.id}: ${msg}`, { machine: m.id }),
        onEnd: () => streams.forget(key, hub),
      };
      let hub: StreamHub;
      if (m.simulated) {
        const sim = simulatorFor(m);
        if (!sim) return { status: 503, error: `no simulator for ${m.kind}` };
        const target = held ? held.target(path, rawQuery) : path + (rawQuery ? `?${rawQuery}` : '');
        const up = simUpstream(sim, target);
        if (!up) return { status: 404, error: 'no socket here' };
        held?.track(up.events);
        hub = new StreamHub(decl, up.socket, hubOpts);
        return { hub };
      }
      const o = await openControllerSocket(m, path, new URLSearchParams(rawQuery), rawQuery, {}, [], held);
      if (!o.ok) return { status: o.status, error: o.error };
      o.stopCollecting();
      hub = new StreamHub(decl, wsUpstream(o.upstream, o.early), hubOpts);
      o.upstream.resume();
      return { hub };
    });
  }

  /**
   * The gateway's watch holds a machine's shared stream open without a viewer (watch.ts) and
   * reads its frames. Throws when the stream cannot be opened now.
   */
  async function holdStream(
    m: MachineEntry,
    path: string,
    onFrame: (frame: string) => void,
    onEnd: () => void,
  ): Promise<() => void> {
    const decl = hintsOf(m).sharing?.streams?.find((d) => d.matches(path));
    if (!decl) throw new Error(`no shared stream at ${path}`);
    const held = await holdSocket(ctx, m);
    if (held && 'status' in held) throw new Error(String(held.body.error));
    const r = await joinHub(m, decl, '', held);
    if ('status' in r) throw new Error(r.error);
    const release = r.hold();
    const offFrame = r.onFrame(onFrame);
    const offEnd = r.onEnded(onEnd);
    return () => {
      offFrame();
      offEnd();
      release();
    };
  }

  return { joinHub, holdStream };
}
