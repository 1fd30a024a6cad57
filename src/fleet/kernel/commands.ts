import { useCallback, useSyncExternalStore } from 'react';
import type { AnyCommand, CommandDecl, CommandRunner, Subscribable } from '../commands';
import type { MachineSnapshot } from '../types';
import { useScheduler } from './use-scheduler';

/** A store as a command reads it: its state and its changes (a zustand store fits). */
export interface Readable<T> extends Subscribable {
  getState(): T;
}

type StatesOf<S> = { [K in keyof S]: S[K] extends Readable<infer T> ? T : never };

/** A command as a family writes it: availability reads only the stores the family named. */
export interface CommandSpec<St, A> extends Omit<CommandDecl<A>, 'available' | 'needs'> {
  available?: (states: St) => true | string;
}

export interface CommandSet<St> {
  /** Declares one command; its id must be unique in the set (ids appear in the audit log). */
  define<A = void>(spec: CommandSpec<St, A>): CommandDecl<A>;
  /** Every command defined so far, by id (MachineSession.commands). */
  readonly all: Readonly<Record<string, AnyCommand>>;
}

/**
 * The one way a family declares its commands. It names the stores availability depends on
 * (always the machine snapshot, plus its own): `available` gets their states and nothing
 * else, and every button of the command subscribes to exactly those stores, so a button never
 * says "not available" while the runner would send the command (or the other way round).
 *
 *   const cmds = defineCommands({ snapshot: ctx.snapshot, xtool: this.store });
 *   this.pause = cmds.define({ id: 'xtool.pause', …, available: ({ xtool }) => … });
 *   this.commands = cmds.all;
 */
export function defineCommands<
  S extends { snapshot: Readable<MachineSnapshot> } & Record<string, Readable<unknown>>,
>(stores: S): CommandSet<StatesOf<S>> {
  const all: Record<string, AnyCommand> = {};
  const needs = Object.values(stores);
  const states = (): StatesOf<S> => {
    const out: Record<string, unknown> = {};
    for (const [k, store] of Object.entries(stores)) out[k] = store.getState();
    return out as StatesOf<S>;
  };
  return {
    define<A = void>(spec: CommandSpec<StatesOf<S>, A>): CommandDecl<A> {
      if (all[spec.id]) throw new Error(`Command ${spec.id} is declared twice`);
      const check = spec.available;
      const decl: CommandDecl<A> = {
        ...spec,
        needs,
        available: check ? () => check(states()) : undefined,
      };
      all[spec.id] = decl as AnyCommand;
      return decl;
    },
    all,
  };
}

/**
 * Why `command` cannot be sent now (null: it can), kept current: subscribed to the runner's
 * state, the machine snapshot and every store the command's availability reads — and to time,
 * since data goes stale without any store changing (the link is then in doubt: commands other
 * than stops are disabled until fresh data arrives).
 */
export function useBlockedReason<A>(
  runner: CommandRunner,
  snapshot: Subscribable,
  command: CommandDecl<A>,
): string | null {
  const needs = command.needs;
  const scheduler = useScheduler();
  const subscribe = useCallback(
    (listener: () => void) => {
      // The moment the data goes stale: a deadline that fresh data moves on (no timer each).
      let staleAt: number | null = null;
      const stale = scheduler.deadline({
        due: () => staleAt,
        fire: () => {
          listener();
          arm();
        },
      });
      const arm = (): void => {
        const ms = runner.msUntilInDoubt();
        staleAt = ms === null ? null : scheduler.now() + ms + 1;
        stale.update();
      };
      const changed = (): void => {
        listener();
        arm();
      };
      const stores: Subscribable[] = [runner.state, snapshot, ...(needs ?? [])];
      const unsubs = [...new Set(stores)].map((s) => s.subscribe(changed));
      arm();
      return () => {
        unsubs.forEach((u) => u());
        stale.cancel();
      };
    },
    [runner, snapshot, needs, scheduler],
  );
  const read = () => runner.blockedReason(command);
  return useSyncExternalStore(subscribe, read, read);
}
