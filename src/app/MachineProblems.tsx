import { Suspense, type ComponentType } from 'react';
import { linkWords, type MachineSession, type TabProps } from '../fleet/contract';
import type { MachineRuntime } from '../fleet/fleet';
import { useSnapshot } from '../fleet/react';
import { Loading, Notice, Panel } from '../ui';
import { RetryIn } from './Age';

/**
 * Why a machine's page shows no fresh data (machine page and kiosk): the link's problem with the
 * next try, the family's login form when the controller wants one, a runtime that cannot start.
 */
export function MachineProblems({
  rt,
  LoginForm,
  showPath = false,
}: {
  rt: MachineRuntime;
  LoginForm: ComponentType<TabProps<MachineSession>> | undefined;
  /** Name the request that failed (the machine page; the kiosk keeps it short). */
  showPath?: boolean;
}) {
  const s = useSnapshot(rt, (x) => ({ link: x.link, problem: x.problem, retryAt: x.retryAt }));
  const session = rt.session;
  return (
    <>
      {s.problem && s.link !== 'online' && (
        <Notice
          tone={s.link === 'protocol-error' ? 'bad' : 'warn'}
          title={`${linkWords(s.link)}${showPath && s.problem.path ? ` (at ${s.problem.path})` : ''}`}
          testId="link-problem"
        >
          {s.problem.message}
          <RetryIn at={s.retryAt} />
        </Notice>
      )}
      {s.link === 'needs-login' && LoginForm && session && (
        <Panel title="Log in to this machine">
          {/* A family's login form may be a chunk of its own. */}
          <Suspense fallback={<Loading />}>
            <LoginForm session={session} />
          </Suspense>
        </Panel>
      )}
      {rt.error && (
        <Notice tone="bad" title="This machine cannot be shown">
          {rt.error}
        </Notice>
      )}
    </>
  );
}
