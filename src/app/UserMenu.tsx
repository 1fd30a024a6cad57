import { useStore } from 'zustand';
import { authStore } from '../fleet/auth';
import { Badge, Button } from '../ui';
import { Link } from './router';

/** Who is signed in, with their role, and the way out. */
export function UserMenu() {
  const { mode, user } = useStore(authStore);
  if (mode !== 'secured') return null;
  if (!user) return <Link to="/login">Sign in</Link>;
  return (
    <div className="ui-row user-menu" data-testid="user-menu">
      <span>{user.name}</span>
      <Badge
        tone={user.role === 'supervisor' ? 'paused' : user.role === 'operator' ? 'info' : 'muted'}
        plain
        testId="user-role"
      >
        {user.role}
      </Badge>
      <Button
        small
        onClick={() => {
          void fetch('/api/logout', { method: 'POST', credentials: 'same-origin' }).finally(() =>
            location.assign('/login'),
          );
        }}
      >
        Sign out
      </Button>
    </div>
  );
}
