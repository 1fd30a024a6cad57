import { vi } from 'vitest';

/**
 * A `fetch` the test drives by hand (works with fake timers, unlike a real server): every call is
 * recorded and waits until the test answers it. An aborted call rejects as fetch does, and so does
 * the body of its answer.
 */

export interface BodyControl {
  stream: ReadableStream<Uint8Array>;
  push(text: string): void;
  end(): void;
  /** The connection breaks partway through the body (what undici reports: "terminated"). */
  cut(): void;
}

export function controlledBody(): BodyControl {
  let ctl: ReadableStreamDefaultController<Uint8Array> | null = null;
  let open = true;
  const stream = new ReadableStream<Uint8Array>({
    start(c) {
      ctl = c;
    },
  });
  const enc = new TextEncoder();
  return {
    stream,
    push: (text) => {
      if (open) ctl?.enqueue(enc.encode(text));
    },
    end: () => {
      if (!open) return;
      open = false;
      ctl?.close();
    },
    cut: () => {
      if (!open) return;
      open = false;
      ctl?.error(new TypeError('terminated'));
    },
  };
}

export interface FetchCall {
  url: string;
  method: string;
  headers: Headers;
  body: BodyInit | null | undefined;
  signal: AbortSignal;
  /** Answer with headers now; `body` a string, or a controlled stream. */
  answer(status: number, body?: string | BodyControl, headers?: Record<string, string>): void;
  /** The request fails without an answer (the console server is unreachable). */
  fail(): void;
  settled: boolean;
}

export interface FakeFetch {
  calls: FetchCall[];
  /** The latest call. */
  last(): FetchCall;
  /** Answer every call as it comes (after the test's own handling, if any returns false). */
  auto: ((call: FetchCall) => boolean) | null;
}

export function installFakeFetch(): FakeFetch {
  const fake: FakeFetch = {
    calls: [],
    last() {
      const c = fake.calls.at(-1);
      if (!c) throw new Error('no fetch call yet');
      return c;
    },
    auto: null,
  };
  vi.stubGlobal('fetch', (input: RequestInfo | URL, init: RequestInit = {}): Promise<Response> => {
    const signal = init.signal ?? new AbortController().signal;
    return new Promise<Response>((resolve, reject) => {
      let body: BodyControl | null = null;
      const call: FetchCall = {
        url: String(input),
        method: init.method ?? 'GET',
        headers: new Headers(init.headers),
        body: init.body,
        signal,
        settled: false,
        answer(status, b, headers = {}) {
          if (call.settled) return;
          call.settled = true;
          if (b !== undefined && typeof b !== 'string') body = b;
          resolve(new Response(typeof b === 'string' ? b : (b?.stream ?? null), { status, headers }));
        },
        fail() {
          if (call.settled) return;
          call.settled = true;
          reject(new TypeError('Failed to fetch'));
        },
      };
      const abort = (): void => {
        if (!call.settled) {
          call.settled = true;
          reject(new DOMException('The operation was aborted.', 'AbortError'));
        }
        body?.cut();
      };
      if (signal.aborted) abort();
      else signal.addEventListener('abort', abort);
      fake.calls.push(call);
      fake.auto?.(call);
    });
  });
  return fake;
}
