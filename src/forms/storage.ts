/** Where unsaved edits are kept: localStorage in the browser, memory elsewhere (tests, Node). */
export interface DraftStorage {
  get(key: string): string | null;
  set(key: string, value: string): void;
  remove(key: string): void;
}

export function memoryDraftStorage(): DraftStorage {
  const m = new Map<string, string>();
  return {
    get: (k) => m.get(k) ?? null,
    set: (k, v) => void m.set(k, v),
    remove: (k) => void m.delete(k),
  };
}

/** localStorage when the page has it (and it works: private modes may throw), else memory. */
export function defaultDraftStorage(): DraftStorage {
  try {
    const ls = globalThis.localStorage;
    if (ls) {
      const probe = '__shopdeck_probe__';
      ls.setItem(probe, '1');
      ls.removeItem(probe);
      return {
        get: (k) => ls.getItem(k),
        set: (k, v) => {
          try {
            ls.setItem(k, v);
          } catch {
            /* quota: the edit stays in memory */
          }
        },
        remove: (k) => ls.removeItem(k),
      };
    }
  } catch {
    /* fall through */
  }
  return memoryDraftStorage();
}
