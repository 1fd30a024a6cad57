/** The controller sockets the gateway shares among viewers: how their frames travel. */

/** How a frame of a shared stream travels to browsers. */
export type FrameClass =
  /**
   * A state frame: a newer one with the same key makes an undelivered older one pointless. A
   * slow or throttled browser gets only the latest of each key; a browser that joins later is
   * first given the latest one of each key whose `replay` is true.
   */
  | { kind: 'latest'; key: string; replay: boolean }
  /**
   * An event (a log line, an alarm): delivered in order, never dropped; a browser too slow for
   * them is closed (1013) and reconnects. `replay`: kept (the last few) for browsers that join later.
   */
  | { kind: 'event'; replay?: boolean };

interface StreamDeclBase {
  /**
   * The socket's canonical path on the controller ("/websocket/everything", "/" for xTool's
   * :8081): what goes upstream and what names the one shared socket, whichever spelling matched.
   */
  path: string;
  /** Whether a browser's (canonical) path is this socket ("/machine" in any spelling DSF takes). */
  matches(path: string): boolean;
  /**
   * The query parameters that choose a different stream on the controller, each with the closed
   * set of values it may take (none: the query is not part of the stream). Only these reach the
   * controller and tell shared sockets apart; any other parameter a browser sends is dropped, and
   * a declared one with another value is refused (400): a browser cannot open a socket per
   * query string.
   */
  query?: Readonly<Record<string, readonly string[]>>;
  /** The upstream socket stays this long after the last viewer left (unless the watch needs it). */
  graceMs: number;
}

/** A stream fanned out frame by frame (xTool :8081 frames, Prunt /websocket/everything). */
export interface FanoutStreamDecl extends StreamDeclBase {
  kind: 'fanout';
  classify(frame: string): FrameClass;
  /**
   * A browser's frame. `reply`: answered by the gateway to that browser alone; `rateMs`: the
   * browser wants `latest` frames at most this often (Prunt's divisor); null: dropped. Nothing a
   * browser sends reaches the shared upstream socket as it is.
   */
  fromBrowser?(frame: string): { reply: string } | { rateMs: number } | null;
  /** The frame sent upstream when the fastest `rateMs` any viewer wants changes (Prunt: the divisor). */
  upstreamRate?(rateMs: number): string;
  /** `rateMs` of a browser that asked for none. */
  defaultRateMs?: number;
}

/** A JSON value (model streams). */
export type JsonValue = null | boolean | number | string | JsonValue[] | { [key: string]: JsonValue };
export type JsonRecord = { [key: string]: JsonValue };

/**
 * A stream whose first frame is a full model and whose later frames are patches, each asked for
 * with an acknowledgement (Duet DSF `WS /machine`: full model, then `OK\n` → one patch; `PING\n`
 * → `PONG\n`). The gateway keeps the merged model; every browser gets the full model first and
 * patches after, each at its own pace (a slow browser gets one patch covering what it missed).
 */
export interface ModelStreamDecl extends StreamDeclBase {
  kind: 'model';
  /** The first frame: the full model, or why it is not one. */
  full(frame: string): JsonRecord | Error;
  /** A later frame applied to the model: the new model and the events it carried (Duet `messages`). */
  apply(model: JsonRecord, frame: string): { model: JsonRecord; events: JsonValue[] } | Error;
  /** A patch that takes `from` to `to` (with `events` carried), as one frame for a browser. */
  diff(from: JsonRecord, to: JsonRecord, events: JsonValue[]): string;
  /** A full model as the first frame for a browser. */
  first(model: JsonRecord): string;
  /** The frame that asks the controller for the next patch ("OK\n"). */
  ack: string;
  /** A browser's frame: its acknowledgement, a keep-alive with the answer to give, or null (dropped). */
  fromBrowser(frame: string): { ack: true } | { reply: string } | null;
  /** Keep-alive the gateway sends upstream when it has heard nothing for `everyMs` ("PING\n"). */
  ping?: { frame: string; everyMs: number; isPong(frame: string): boolean };
}

export type SharedStreamDecl = FanoutStreamDecl | ModelStreamDecl;
